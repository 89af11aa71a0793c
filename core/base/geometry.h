#pragma once
/// Geometry shared by every stage: points, axis-aligned boxes, segments and the segment–box test.
///
/// Structures work in `float` (as engines do); ground truth works in `double` (see ground_truth.h).
/// A segment is the closed set {P0 + t·(P1 − P0) : t ∈ [0, 1]} (thesis §3.2: P0/P1) and a box is
/// closed, so touching a face, an edge or a corner counts as a hit.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace rcb {

template <typename T>
struct Vec3T {
    T x = 0, y = 0, z = 0;

    constexpr T operator[](int axis) const { return axis == 0 ? x : (axis == 1 ? y : z); }
    constexpr T& operator[](int axis) { return axis == 0 ? x : (axis == 1 ? y : z); }

    friend constexpr Vec3T operator+(Vec3T a, Vec3T b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
    friend constexpr Vec3T operator-(Vec3T a, Vec3T b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
    friend constexpr Vec3T operator*(Vec3T a, T s) { return {a.x * s, a.y * s, a.z * s}; }
    friend constexpr bool operator==(Vec3T a, Vec3T b) = default;

    template <typename U>
    constexpr Vec3T<U> as() const {
        return {U(x), U(y), U(z)};
    }
};

using Vec3 = Vec3T<float>;
using Vec3d = Vec3T<double>;

template <typename T>
constexpr Vec3T<T> min(Vec3T<T> a, Vec3T<T> b) {
    return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
template <typename T>
constexpr Vec3T<T> max(Vec3T<T> a, Vec3T<T> b) {
    return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}

template <typename T>
constexpr T dot(Vec3T<T> a, Vec3T<T> b) {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}
template <typename T>
constexpr Vec3T<T> cross(Vec3T<T> a, Vec3T<T> b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

template <typename T>
struct AabbT {
    Vec3T<T> min, max;

    /// The empty box: the identity of `merge`.
    static constexpr AabbT empty() {
        constexpr T inf = std::numeric_limits<T>::infinity();
        return {{inf, inf, inf}, {-inf, -inf, -inf}};
    }
    constexpr bool is_empty() const { return min.x > max.x || min.y > max.y || min.z > max.z; }
    constexpr Vec3T<T> extent() const { return max - min; }
    constexpr Vec3T<T> center() const { return (min + max) * T(0.5); }
    constexpr T longest_edge() const { return std::max({max.x - min.x, max.y - min.y, max.z - min.z}); }
    /// Half the surface area: the SAH only needs ratios, and this saves a multiply.
    constexpr T half_area() const {
        Vec3T<T> e = extent();
        return e.x * e.y + e.y * e.z + e.z * e.x;
    }
    constexpr bool contains(const AabbT& b) const {
        return min.x <= b.min.x && min.y <= b.min.y && min.z <= b.min.z && b.max.x <= max.x && b.max.y <= max.y &&
               b.max.z <= max.z;
    }
    constexpr bool overlaps(const AabbT& b) const {
        return min.x <= b.max.x && b.min.x <= max.x && min.y <= b.max.y && b.min.y <= max.y && min.z <= b.max.z &&
               b.min.z <= max.z;
    }
    friend constexpr AabbT merge(const AabbT& a, const AabbT& b) {
        return {rcb::min(a.min, b.min), rcb::max(a.max, b.max)};
    }
    friend constexpr bool operator==(const AabbT&, const AabbT&) = default;

    template <typename U>
    constexpr AabbT<U> as() const {
        return {min.template as<U>(), max.template as<U>()};
    }
};

using Aabb = AabbT<float>;
using Aabbd = AabbT<double>;

template <typename T>
struct SegmentT {
    Vec3T<T> p0, p1;
    constexpr Vec3T<T> delta() const { return p1 - p0; }
    constexpr Vec3T<T> at(T t) const { return p0 + (p1 - p0) * t; }
    friend constexpr bool operator==(const SegmentT&, const SegmentT&) = default;
};

using Segment = SegmentT<float>;
using Segmentd = SegmentT<double>;

/// `a > b ? a : b`, written so that a NaN in `a` yields `b`. The slab test relies on it: a NaN
/// slab bound only arises as 0·∞ for a segment parallel to the slab with its start exactly on a
/// face, and such a slab constrains nothing (see SegmentSlabs).
template <typename T>
constexpr T max_ignoring_nan(T a, T b) {
    return a > b ? a : b;
}
template <typename T>
constexpr T min_ignoring_nan(T a, T b) {
    return a < b ? a : b;
}

/// A segment prepared for many slab tests (Kay & Kajiya's slabs, with the sign-indexed bounds of
/// Williams et al. 2005, "An efficient and robust ray–box intersection algorithm").
///
/// Exactness for axis-parallel segments: if d_a = 0 then inv_a = ±∞ and the slab bounds are
/// (b − o)·inv_a = ±∞, or NaN when b = o. With the near bound taken from the box side facing the
/// direction's sign, a start strictly inside the slab gives (−∞, +∞), outside gives an empty
/// interval, and a start on a face gives NaN for that face, which `max_ignoring_nan` /
/// `min_ignoring_nan` drop: the closed slab contains the start, so the axis constrains nothing.
template <typename T>
struct SegmentSlabsT {
    Vec3T<T> origin;
    Vec3T<T> inv;        // 1 / (p1 − p0) per axis, ±∞ for a zero component
    int near_is_max[3];  // 1 when the direction's sign bit is set: the near face is the box's max

    constexpr explicit SegmentSlabsT(const SegmentT<T>& s) : origin(s.p0) {
        Vec3T<T> d = s.delta();
        for (int a = 0; a < 3; ++a) {
            inv[a] = T(1) / d[a];
            near_is_max[a] = std::signbit(d[a]) ? 1 : 0;
        }
    }

    /// Parameter interval [t_near, t_far] of the segment inside the box, clipped to
    /// [t_min, t_max] (the segment itself: [0, 1]); the segment meets the box iff t_near <= t_far.
    /// Always inlined: it is the inner loop of every traversal, and where a file holds several
    /// traversals GCC otherwise calls it out of line.
    [[gnu::always_inline]] constexpr bool clip(const AabbT<T>& box, T& t_near, T& t_far, T t_min = 0,
                                               T t_max = 1) const {
        T tn = t_min, tf = t_max;
        for (int a = 0; a < 3; ++a) {
            T lo = ((near_is_max[a] ? box.max[a] : box.min[a]) - origin[a]) * inv[a];
            T hi = ((near_is_max[a] ? box.min[a] : box.max[a]) - origin[a]) * inv[a];
            tn = max_ignoring_nan(lo, tn);
            tf = min_ignoring_nan(hi, tf);
        }
        t_near = tn;
        t_far = tf;
        return tn <= tf;
    }
    constexpr bool hits(const AabbT<T>& box) const {
        T tn, tf;
        return clip(box, tn, tf);
    }
};

using SegmentSlabs = SegmentSlabsT<float>;
using SegmentSlabsd = SegmentSlabsT<double>;

/// The closed segment meets the closed box.
template <typename T>
constexpr bool segment_hits_box(const SegmentT<T>& s, const AabbT<T>& box) {
    return SegmentSlabsT<T>(s).hits(box);
}

/// True when every coordinate is finite (no NaN, no ±∞).
template <typename T>
constexpr bool is_finite(const Vec3T<T>& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

/// The largest |coordinate| of a box: the scale the peers pad their library's bounds against.
template <typename T>
constexpr T largest_coordinate(const AabbT<T>& b) {
    return std::max({std::abs(b.min.x), std::abs(b.min.y), std::abs(b.min.z), std::abs(b.max.x), std::abs(b.max.y),
                     std::abs(b.max.z)});
}

}  // namespace rcb
