# CMake toolchain for cross-building the CPU module for aarch64 Linux with Debian's cross compiler
# (crossbuild-essential-arm64: aarch64-linux-gnu-g++); scripts/check_aarch64.sh uses it.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
