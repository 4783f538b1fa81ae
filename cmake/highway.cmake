# Google Highway's headers (the vector paths use only its headers, static targets, no library): sets HWY_INCLUDE_DIR
# and GBV_HWY_SOURCE (how they were found), or stops the configure with one line saying why.
#
# 1. GBVIEWER_HIGHWAY_ARCHIVE=FILE (CMake variable or environment): that local copy of the pinned release tarball.
# 2. The installed headers: -DHWY_INCLUDE_DIR=DIR, else hwy/highway.h where the compiler looks (Debian: libhwy-dev).
# 3. Unless GBVIEWER_FETCH_HIGHWAY is OFF (CMake option or environment): the pinned release downloaded at configure
#    time into the build folder, from GitHub or else Debian's archive (its orig tarball is GitHub's tarball, byte for
#    byte: the same SHA-256 as Homebrew's and Spack's recipes pin), and checked against that SHA-256.
# Nothing of Highway is kept in the repository.
set(GBV_HWY_VERSION 1.0.3)
set(GBV_HWY_SHA256 566fc77315878473d9a6bd815f7de78c73734acdcb745c3dde8579560ac5440e)
set(GBV_HWY_URLS "https://github.com/google/highway/archive/refs/tags/${GBV_HWY_VERSION}.tar.gz"
    "https://deb.debian.org/debian/pool/main/h/highway/highway_${GBV_HWY_VERSION}.orig.tar.gz")

option(GBVIEWER_FETCH_HIGHWAY "Download the pinned Highway release when its headers are not installed" ON)
if(DEFINED ENV{GBVIEWER_FETCH_HIGHWAY} AND NOT "$ENV{GBVIEWER_FETCH_HIGHWAY}" STREQUAL "")
  set(GBVIEWER_FETCH_HIGHWAY "$ENV{GBVIEWER_FETCH_HIGHWAY}")
endif()
set(GBVIEWER_HIGHWAY_ARCHIVE "$ENV{GBVIEWER_HIGHWAY_ARCHIVE}" CACHE FILEPATH
    "A local copy of the pinned Highway tarball (highway-${GBV_HWY_VERSION}.tar.gz), used instead of any other")

# Unpacks `archive` (after its SHA-256 check) into the build folder and sets HWY_INCLUDE_DIR to it.
function(gbv_unpack_highway archive)
  file(SHA256 "${archive}" sum)
  if(NOT sum STREQUAL GBV_HWY_SHA256)
    gbv_fail("gbviewer: ${archive} is not Highway ${GBV_HWY_VERSION}'s release tarball (SHA-256 ${sum}, expected "
             "${GBV_HWY_SHA256})")
  endif()
  set(dir "${CMAKE_BINARY_DIR}/_deps")
  if(NOT EXISTS "${dir}/highway-${GBV_HWY_VERSION}/hwy/highway.h")
    file(ARCHIVE_EXTRACT INPUT "${archive}" DESTINATION "${dir}" PATTERNS "highway-${GBV_HWY_VERSION}/hwy")
  endif()
  set(HWY_INCLUDE_DIR "${dir}/highway-${GBV_HWY_VERSION}" CACHE PATH "Google Highway's headers" FORCE)
endfunction()

# Downloads the pinned tarball into the build folder (once) and unpacks it; one line and a stop when no URL gives it.
function(gbv_fetch_highway)
  set(archive "${CMAKE_BINARY_DIR}/_deps/highway-${GBV_HWY_VERSION}.tar.gz")
  if(EXISTS "${archive}")
    file(SHA256 "${archive}" sum)
  endif()
  set(tried "")
  foreach(url ${GBV_HWY_URLS})
    if(sum STREQUAL GBV_HWY_SHA256)
      break()
    endif()
    message(STATUS "gbviewer: downloading Highway ${GBV_HWY_VERSION} from ${url}")
    file(DOWNLOAD "${url}" "${archive}.part" STATUS status TIMEOUT 120 INACTIVITY_TIMEOUT 30)
    list(GET status 0 code)
    list(GET status 1 why)
    if(code EQUAL 0)
      file(SHA256 "${archive}.part" sum)
      if(sum STREQUAL GBV_HWY_SHA256)
        file(RENAME "${archive}.part" "${archive}")
      else()
        set(why "SHA-256 ${sum} is not the pinned ${GBV_HWY_SHA256}")
      endif()
    endif()
    file(REMOVE "${archive}.part")
    string(APPEND tried " ${url} (${why})")
  endforeach()
  if(NOT sum STREQUAL GBV_HWY_SHA256)
    gbv_fail("gbviewer: Google Highway's headers (hwy/highway.h) are not installed and the download of Highway "
             "${GBV_HWY_VERSION} failed:${tried}. Without them the CPU module would have no vector paths (3-5x "
             "slower blend): install them (Debian/Ubuntu: apt-get install libhwy-dev, or -DHWY_INCLUDE_DIR=DIR), "
             "give the tarball with GBVIEWER_HIGHWAY_ARCHIVE=FILE, or build scalar-only on purpose with "
             "GBVIEWER_SCALAR_ONLY=1")
  endif()
  gbv_unpack_highway("${archive}")
endfunction()

if(GBVIEWER_HIGHWAY_ARCHIVE)
  gbv_unpack_highway("${GBVIEWER_HIGHWAY_ARCHIVE}")
  set(GBV_HWY_SOURCE "the archive ${GBVIEWER_HIGHWAY_ARCHIVE}")
  return()
endif()
find_path(HWY_INCLUDE_DIR hwy/highway.h)  # Debian: libhwy-dev; headers only
if(HWY_INCLUDE_DIR)
  set(GBV_HWY_SOURCE "installed, ${HWY_INCLUDE_DIR}")
elseif(GBVIEWER_FETCH_HIGHWAY)
  gbv_fetch_highway()
  set(GBV_HWY_SOURCE "downloaded")
else()
  gbv_fail("gbviewer: Google Highway's headers (hwy/highway.h) not found and GBVIEWER_FETCH_HIGHWAY is off, so the "
           "CPU module would have no vector paths (3-5x slower blend): install them (Debian/Ubuntu: apt-get install "
           "libhwy-dev, or -DHWY_INCLUDE_DIR=DIR), give the tarball with GBVIEWER_HIGHWAY_ARCHIVE=FILE, or build "
           "scalar-only on purpose with GBVIEWER_SCALAR_ONLY=1 (pip: GBVIEWER_SCALAR_ONLY=1 pip install .)")
endif()
