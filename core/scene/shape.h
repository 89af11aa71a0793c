#pragma once
/// Exact object shapes inside their boxes: the ray–object test of the thesis' model (eq. 5.3,
/// C_RO) and what makes a box hit a bv-caused false positive (eq. 5.2, N_BFP).
///
/// An object is a box (the default: the box is the shape) or one of the shapes below; a shaped
/// object's box is its bounds, computed by shape_bounds and rounded outward, so the box always
/// contains the shape. Structures work on the boxes; the narrow phase (narrow_phase.h) and the
/// ground truth (ground_truth.h) test the shapes. Parameters, all float:
///
///     triangle  a[3] b[3] c[3]
///     obb       centre[3] half_extent[3] rotation quaternion (w, x, y, z), unit within 1e-3
///     sphere    centre[3] radius
///     capsule   p0[3] p1[3] radius: the points within radius of the segment p0–p1
///
/// Triangles are tested watertight in float (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
/// Intersection"): a segment through a shared edge or vertex hits at least one of the triangles.

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>

#include "core/base/geometry.h"

namespace rcb {

enum class ShapeKind : std::uint8_t { box = 0, triangle = 1, obb = 2, sphere = 3, capsule = 4 };
inline constexpr int kShapeKinds = 5;

/// Floats a shape of this kind stores (0 for a box: its box is the shape).
constexpr int shape_floats(ShapeKind k) {
    constexpr int n[kShapeKinds] = {0, 9, 10, 4, 7};
    return n[int(k)];
}
std::string_view shape_name(ShapeKind k);

struct Shape {
    ShapeKind kind = ShapeKind::box;
    std::array<float, 10> v{};  ///< the first shape_floats(kind) are used, the rest are 0

    static Shape triangle(Vec3 a, Vec3 b, Vec3 c);
    /// `q` = (w, x, y, z), normalised here.
    static Shape obb(Vec3 centre, Vec3 half_extent, const std::array<float, 4>& q);
    static Shape sphere(Vec3 centre, float radius);
    static Shape capsule(Vec3 p0, Vec3 p1, float radius);

    Vec3 point(int i) const { return {v[3 * i], v[3 * i + 1], v[3 * i + 2]}; }
    /// A sphere or capsule as the points within radius() of core(): its centre (a zero-length
    /// segment) or its axis.
    template <typename T>
    SegmentT<T> core() const {
        const Vec3T<T> p0 = point(0).as<T>();
        return {p0, kind == ShapeKind::sphere ? p0 : point(1).as<T>()};
    }
    float radius() const { return kind == ShapeKind::sphere ? v[3] : v[6]; }
    friend bool operator==(const Shape&, const Shape&) = default;
};

/// What is wrong with a shape's parameters ("" when nothing): a non-finite value, a coordinate
/// beyond ±limit, a negative half extent or radius, a rotation that is not a unit quaternion.
/// Degenerate triangles and zero-thickness boxes are valid shapes (they are hit edge-on or not at
/// all, like any engine's).
std::string shape_problem(const Shape& shape, double limit);

/// The interval of n·p over the points p of a valid, non-box shape, in double (n need not be a
/// unit vector): the shape's bounds along n. shape_bounds takes it along the axes; the k-DOPs and
/// oriented boxes around a shape (query_level.h) along their directions.
std::pair<double, double> shape_extent(const Shape& shape, const Vec3d& n);

/// Bounds of a valid shape, rounded outward to float: the box contains the shape exactly.
Aabb shape_bounds(const Shape& shape);

/// The largest float <= x, and the smallest float >= x: outward rounding of bounds.
float float_below(double x);
float float_above(double x);

/// The narrow phase: whether the closed segment meets the shape, and (if `t` is given) the
/// parameter in [0, 1] where it first does. Triangles and obbs are tested in float; spheres and
/// capsules in double relative to their centre (float's closest-point test overflows and cancels
/// at large coordinates). Every kind agrees with the ground truth over the format's coordinate
/// range (±1e15). A box-kind shape is not tested here (its box test is the test) and yields false.
bool segment_hits_shape(const Segment& segment, const Shape& shape, float* t = nullptr);

/// Closest points of two closed segments (Ericson 2005, "Real-Time Collision Detection" §5.1.9):
/// parameters s on `a`, t on `b`, and the squared distance. Zero-length segments are points.
template <typename T>
struct ClosestPoints {
    T s = 0, t = 0, distance2 = 0;
};
template <typename T>
ClosestPoints<T> closest_points(const SegmentT<T>& a, const SegmentT<T>& b) {
    const Vec3T<T> d1 = a.delta(), d2 = b.delta(), r = a.p0 - b.p0;
    const T aa = dot(d1, d1), e = dot(d2, d2), f = dot(d2, r);
    auto clamp01 = [](T x) { return std::clamp(x, T(0), T(1)); };
    ClosestPoints<T> c;
    if (aa == 0 && e == 0) {
    } else if (aa == 0) {
        c.t = clamp01(f / e);
    } else {
        const T cc = dot(d1, r);
        if (e == 0) {
            c.s = clamp01(-cc / aa);
        } else {
            const T bb = dot(d1, d2), denom = aa * e - bb * bb;
            c.s = denom > 0 ? clamp01((bb * f - cc * e) / denom) : T(0);
            c.t = (bb * c.s + f) / e;
            if (c.t < 0) {
                c.t = 0;
                c.s = clamp01(-cc / aa);
            } else if (c.t > 1) {
                c.t = 1;
                c.s = clamp01((bb - cc) / aa);
            }
        }
    }
    const Vec3T<T> gap = a.at(c.s) - b.at(c.t);
    c.distance2 = dot(gap, gap);
    return c;
}

/// Rotation matrix (rows) of an obb's quaternion, in T.
template <typename T>
std::array<Vec3T<T>, 3> obb_axes(const Shape& s) {
    T w = s.v[6], x = s.v[7], y = s.v[8], z = s.v[9];
    const T n = std::sqrt(w * w + x * x + y * y + z * z);
    w /= n, x /= n, y /= n, z /= n;
    // Columns of R are the box's local axes in world space; returned as those three vectors.
    return {Vec3T<T>{1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)},
            Vec3T<T>{2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)},
            Vec3T<T>{2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)}};
}

}  // namespace rcb
