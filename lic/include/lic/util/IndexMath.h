// Integer clamp, floor, ceil and floor division for the hot loops, always inlined. x86-64's baseline has no
// rounding instruction: std::floor is a call into libm or a long inline sequence, while these are
// a conversion, a compare and a subtract, with the same integer for |x| < 2³¹.
#pragma once

namespace lic {

namespace detail {
/// std::clamp for ints, always inlined: in the tracer's long lockstep loop GCC stops inlining
/// std::clamp (it takes references) and calls it 35 times per step pair.
[[gnu::always_inline]] inline int clampIndex(int v, int lo, int hi) { return v < lo ? lo : (hi < v ? hi : v); }
/// std::floor for |x| < 2³¹, as an int (double(floorIndex(x)) is std::floor(x) there).
[[gnu::always_inline]] inline int floorIndex(double x)
{
    const int i = int(x);
    return double(i) > x ? i - 1 : i;
}
[[gnu::always_inline]] inline int floorIndex(float x)
{
    const int i = int(x);
    return float(i) > x ? i - 1 : i;
}
/// std::ceil for |x| < 2³¹, as an int, without a call (see floorIndex).
[[gnu::always_inline]] inline int ceilIndex(double x) { return -floorIndex(-x); }
[[gnu::always_inline]] inline int ceilIndex(float x) { return -floorIndex(-x); }
/// a / b rounded towards −∞ (b > 0): the block or brick of a possibly negative coordinate.
inline int floorDiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }
} // namespace detail

} // namespace lic
