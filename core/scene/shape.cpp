#include "core/scene/shape.h"

#include <cmath>
#include <cstdio>
#include <limits>

namespace rcb {
namespace {

/// Woop, Benthin & Wald 2013, §3: shear the triangle into the segment's frame, where the edge
/// functions U, V, W are exact in sign up to rounding and an edge shared by two triangles gets the
/// same value (of opposite sign) in both, so nothing slips between them.
bool hits_triangle(const Segment& s, const Shape& tri, float* t_out) {
    const Vec3 d = s.delta();
    int kz = 0;
    if (std::abs(d.y) > std::abs(d[kz])) kz = 1;
    if (std::abs(d.z) > std::abs(d[kz])) kz = 2;
    if (d[kz] == 0) return false;  // a point: it lies on the (measure-zero) triangle only by touch
    int kx = (kz + 1) % 3, ky = (kx + 1) % 3;
    if (d[kz] < 0) std::swap(kx, ky);  // keeps the winding, so U, V, W keep their meaning
    const float sx = d[kx] / d[kz], sy = d[ky] / d[kz], sz = 1.0f / d[kz];
    const Vec3 a = tri.point(0) - s.p0, b = tri.point(1) - s.p0, c = tri.point(2) - s.p0;
    const float ax = a[kx] - sx * a[kz], ay = a[ky] - sy * a[kz];
    const float bx = b[kx] - sx * b[kz], by = b[ky] - sy * b[kz];
    const float cx = c[kx] - sx * c[kz], cy = c[ky] - sy * c[kz];
    float u = cx * by - cy * bx, v = ax * cy - ay * cx, w = bx * ay - by * ax;
    if (u == 0 || v == 0 || w == 0) {  // on an edge in float: decide it in double (the paper's fallback)
        u = float(double(cx) * double(by) - double(cy) * double(bx));
        v = float(double(ax) * double(cy) - double(ay) * double(cx));
        w = float(double(bx) * double(ay) - double(by) * double(ax));
    }
    if ((u < 0 || v < 0 || w < 0) && (u > 0 || v > 0 || w > 0)) return false;
    float det = u + v + w;
    if (det == 0) return false;  // the segment lies in the triangle's plane: a touch at most
    float tt = u * (sz * a[kz]) + v * (sz * b[kz]) + w * (sz * c[kz]);
    if (det < 0) det = -det, tt = -tt;
    if (tt < 0 || tt > det) return false;  // the plane is crossed outside the segment
    if (t_out) *t_out = tt / det;
    return true;
}

bool hits_obb(const Segment& s, const Shape& box, float* t_out) {
    const std::array<Vec3, 3> axis = obb_axes<float>(box);
    const Vec3 c = box.point(0);
    const Vec3 l0 = s.p0 - c, l1 = s.p1 - c;
    const Segment local{{dot(l0, axis[0]), dot(l0, axis[1]), dot(l0, axis[2])},
                        {dot(l1, axis[0]), dot(l1, axis[1]), dot(l1, axis[2])}};
    const Vec3 h = box.point(1);
    float tn, tf;
    if (!SegmentSlabs(local).clip(Aabb{{-h.x, -h.y, -h.z}, h}, tn, tf)) return false;
    if (t_out) *t_out = tn;
    return true;
}

/// First t in [0, t_hit] where `inside(t)` holds, for a predicate that holds on an interval
/// containing t_hit (a line meets a convex shape in an interval): bisection, 24 steps (float's
/// precision of t).
template <class Inside>
double first_inside(double t_hit, Inside&& inside) {
    if (inside(0.0)) return 0.0;
    double lo = 0.0, hi = t_hit;
    for (int i = 0; i < 24; ++i) {
        const double mid = 0.5 * (lo + hi);
        (inside(mid) ? hi : lo) = mid;
    }
    return hi;
}

/// Spheres and capsules: the closest points of the segment and the core (Ericson 2005, §5.1.9)
/// in double, relative to the core's midpoint. In float the test is wrong at large coordinates:
/// the denominator |d1|²·|d2|² − (d1·d2)² overflows once lengths reach ~1e10, and for long,
/// nearly parallel segments it cancels to noise, which puts the closest point far from the true
/// one. The inputs are floats, exact in double; double's products stay finite up to the format's
/// ±1e15 and its rounding is far inside the truth's tolerance (ground_truth.h), so the answer
/// agrees with the double-precision truth at every scale the format allows.
bool hits_round(const Segment& s, const Shape& shape, float* t_out) {
    const SegmentT<double> world = shape.core<double>();
    const Vec3d o = (world.p0 + world.p1) * 0.5;
    const SegmentT<double> axis{world.p0 - o, world.p1 - o};
    const SegmentT<double> seg{s.p0.as<double>() - o, s.p1.as<double>() - o};
    const double r = shape.radius(), r2 = r * r;
    const ClosestPoints<double> c = closest_points(seg, axis);
    if (!(c.distance2 <= r2)) return false;
    if (t_out)
        *t_out = float(first_inside(c.s, [&](double t) {
            const Vec3d p = seg.at(t);
            return closest_points(SegmentT<double>{p, p}, axis).distance2 <= r2;
        }));
    return true;
}

}  // namespace

std::string_view shape_name(ShapeKind k) {
    constexpr std::string_view names[kShapeKinds] = {"box", "triangle", "obb", "sphere", "capsule"};
    return names[int(k)];
}

Shape Shape::triangle(Vec3 a, Vec3 b, Vec3 c) {
    Shape s;
    s.kind = ShapeKind::triangle;
    for (int i = 0; i < 3; ++i) s.v[i] = a[i], s.v[3 + i] = b[i], s.v[6 + i] = c[i];
    return s;
}

Shape Shape::obb(Vec3 centre, Vec3 half_extent, const std::array<float, 4>& q) {
    Shape s;
    s.kind = ShapeKind::obb;
    const double n = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] + double(q[3]) * q[3]);
    for (int i = 0; i < 3; ++i) s.v[i] = centre[i], s.v[3 + i] = half_extent[i];
    for (int i = 0; i < 4; ++i) s.v[6 + i] = n > 0 ? float(q[i] / n) : q[i];
    return s;
}

Shape Shape::sphere(Vec3 centre, float radius) {
    Shape s;
    s.kind = ShapeKind::sphere;
    for (int i = 0; i < 3; ++i) s.v[i] = centre[i];
    s.v[3] = radius;
    return s;
}

Shape Shape::capsule(Vec3 p0, Vec3 p1, float radius) {
    Shape s;
    s.kind = ShapeKind::capsule;
    for (int i = 0; i < 3; ++i) s.v[i] = p0[i], s.v[3 + i] = p1[i];
    s.v[6] = radius;
    return s;
}

std::string shape_problem(const Shape& s, double limit) {
    if (int(s.kind) >= kShapeKinds) return "unknown shape kind " + std::to_string(int(s.kind));
    const int n = shape_floats(s.kind);
    for (int i = 0; i < n; ++i)
        if (!std::isfinite(s.v[i])) return std::string(shape_name(s.kind)) + " has a non-finite value";
    for (int i = n; i < int(s.v.size()); ++i)
        if (s.v[i] != 0) return std::string(shape_name(s.kind)) + " has values beyond its " + std::to_string(n);
    auto beyond = [&](int first, int count) {
        for (int i = first; i < first + count; ++i)
            if (std::abs(double(s.v[i])) > limit) return true;
        return false;
    };
    switch (s.kind) {
        case ShapeKind::box:
            return "";
        case ShapeKind::triangle:
            if (beyond(0, 9)) break;
            return "";
        case ShapeKind::obb: {
            if (s.v[3] < 0 || s.v[4] < 0 || s.v[5] < 0) return "obb has a negative half extent";
            double q2 = 0;
            for (int i = 6; i < 10; ++i) q2 += double(s.v[i]) * s.v[i];
            if (std::abs(std::sqrt(q2) - 1) > 1e-3)
                return "obb rotation is not a unit quaternion (|q| = " + std::to_string(std::sqrt(q2)) + ")";
            if (beyond(0, 6)) break;
            const Aabbd b = shape_bounds(s).as<double>();
            if (std::max({-b.min.x, -b.min.y, -b.min.z, b.max.x, b.max.y, b.max.z}) > limit) break;
            return "";
        }
        case ShapeKind::sphere:
        case ShapeKind::capsule: {
            const int r = s.kind == ShapeKind::sphere ? 3 : 6;
            if (s.v[r] < 0) return std::string(shape_name(s.kind)) + " has a negative radius";
            if (beyond(0, r) || beyond(r, 1)) break;
            const Aabbd b = shape_bounds(s).as<double>();
            if (std::max({-b.min.x, -b.min.y, -b.min.z, b.max.x, b.max.y, b.max.z}) > limit) break;
            return "";
        }
    }
    char shown[32];  // as the coordinate check prints it: ±1e+15, not ±1000000000000000.000000
    std::snprintf(shown, sizeof shown, "%g", limit);
    return std::string(shape_name(s.kind)) + " reaches beyond ±" + shown;
}

float float_below(double x) {
    float f = float(x);
    if (double(f) > x) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
    return f;
}
float float_above(double x) {
    float f = float(x);
    if (double(f) < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
    return f;
}

std::pair<double, double> shape_extent(const Shape& s, const Vec3d& n) {
    auto at = [&](int i) { return dot(s.point(i).as<double>(), n); };
    switch (s.kind) {
        case ShapeKind::triangle:
            return {std::min({at(0), at(1), at(2)}), std::max({at(0), at(1), at(2)})};
        case ShapeKind::obb: {
            const std::array<Vec3d, 3> axis = obb_axes<double>(s);
            const Vec3d h = s.point(1).as<double>();
            const double reach =
                std::abs(dot(axis[0], n)) * h.x + std::abs(dot(axis[1], n)) * h.y + std::abs(dot(axis[2], n)) * h.z;
            return {at(0) - reach, at(0) + reach};
        }
        case ShapeKind::sphere:
        case ShapeKind::capsule: {
            const SegmentT<double> core = s.core<double>();
            const double r = s.radius() * std::sqrt(dot(n, n));
            const double a = dot(core.p0, n), b = dot(core.p1, n);
            return {std::min(a, b) - r, std::max(a, b) + r};
        }
        case ShapeKind::box:
            break;
    }
    return {0, 0};
}

Aabb shape_bounds(const Shape& s) {
    if (s.kind == ShapeKind::box) return Aabb::empty();
    Aabb b;
    for (int a = 0; a < 3; ++a) {
        Vec3d axis;
        axis[a] = 1;
        const auto [lo, hi] = shape_extent(s, axis);
        b.min[a] = float_below(lo), b.max[a] = float_above(hi);
    }
    return b;
}

bool segment_hits_shape(const Segment& segment, const Shape& shape, float* t) {
    switch (shape.kind) {
        case ShapeKind::triangle:
            return hits_triangle(segment, shape, t);
        case ShapeKind::obb:
            return hits_obb(segment, shape, t);
        case ShapeKind::sphere:
        case ShapeKind::capsule:
            return hits_round(segment, shape, t);
        case ShapeKind::box:
            break;
    }
    return false;
}

}  // namespace rcb
