// float32 -> float16 (IEEE binary16) bits, rounded to nearest even as numpy's astype(float16) and the F16C
// instruction (VCVTPS2PH) round; a NaN stays a NaN of the same sign, quietened, with its payload's top bits (as
// VCVTPS2PH does). In software so that every compiler builds it (Clang 14 has no _Float16 on x86-64) and no
// instruction set is assumed; testing.half_mismatches() checks it against the F16C instruction on every float.
#pragma once

#include <cstdint>
#include <cstring>

namespace gbv {

inline uint16_t half_bits(float f) {
    uint32_t x;
    std::memcpy(&x, &f, sizeof x);
    const uint32_t sign = (x >> 16) & 0x8000u, ax = x & 0x7fffffffu;
    if (ax >= 0x7f800000u)  // infinity, NaN
        return (uint16_t)(sign | 0x7c00u | (ax > 0x7f800000u ? 0x200u | ((ax >> 13) & 0x3ffu) : 0u));
    if (ax >= 0x477ff000u) return (uint16_t)(sign | 0x7c00u);  // 65520 and above round to infinity
    if (ax >= 0x38800000u) {  // a normal float16 (2^-14 and above)
        uint32_t r = ax - 0x38000000u;  // exponent rebiased from 127 to 15
        r += 0xfffu + ((r >> 13) & 1u);  // round the 13 dropped bits to nearest even
        return (uint16_t)(sign | (r >> 13));
    }
    if (ax < 0x33000000u) return (uint16_t)sign;  // below 2^-25: zero (2^-25 itself ties to even, zero, below)
    // a subnormal float16: the significand in units of 2^-24, rounded to nearest even (1024 is the smallest normal)
    const uint32_t mant = (ax & 0x7fffffu) | 0x800000u, shift = 126u - (ax >> 23);  // shift in 14..24
    const uint32_t rem = mant & ((1u << shift) - 1u), halfway = 1u << (shift - 1u);
    uint32_t m = mant >> shift;
    m += (rem > halfway) | ((rem == halfway) & (m & 1u));
    return (uint16_t)(sign | m);
}

}  // namespace gbv
