#include "accel/narrow/leaf_volume.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace rcb {

ParamSpec leaf_bv_param_spec() {
    ParamSpec p;
    p.name = "leaf_bv";
    p.kind = ParamKind::choice;
    p.choices = {"aabb", "kdop14", "kdop18", "obb"};
    p.default_value = "aabb";
    p.doc = "bounding volume a shaped object's box hit is tested against next: aabb (none), kdop14, kdop18, obb";
    p.tunable = false;
    p.recorded_when_default = false;
    return p;
}

LeafBv leaf_bv_of(const nlohmann::json& params) {
    if (!params.is_object() || !params.contains("leaf_bv")) return LeafBv::aabb;
    const std::string v = params.at("leaf_bv").get<std::string>();
    return v == "kdop14" ? LeafBv::kdop14
                         : (v == "kdop18" ? LeafBv::kdop18 : (v == "obb" ? LeafBv::obb : LeafBv::aabb));
}

namespace {

// Directions of the diagonal slabs (the box's slabs are the box): kdop14's four cube diagonals,
// kdop18's six face diagonals (Klosowski et al. 1998, "Efficient collision detection using bounding
// volume hierarchies of k-DOPs").
constexpr int kDiag14[4][3] = {{1, 1, 1}, {1, 1, -1}, {1, -1, 1}, {-1, 1, 1}};
constexpr int kDiag18[6][3] = {{1, 1, 0}, {1, 0, 1}, {0, 1, 1}, {1, -1, 0}, {1, 0, -1}, {0, 1, -1}};

int diagonals(LeafBv k) { return k == LeafBv::kdop14 ? 4 : (k == LeafBv::kdop18 ? 6 : 0); }
Vec3d diagonal(LeafBv k, int i) {
    const int* d = k == LeafBv::kdop14 ? kDiag14[i] : kDiag18[i];
    return {double(d[0]), double(d[1]), double(d[2])};
}

/// An oriented box around the shape, or a box-kind shape when it would be no tighter than the box.
Shape enclosing_obb(const Object& o) {
    const Shape& s = o.shape;
    if (s.kind == ShapeKind::obb) return s;
    Vec3d u, v, w;  // orthonormal axes
    if (s.kind == ShapeKind::triangle) {
        const Vec3d a = s.point(0).as<double>(), b = s.point(1).as<double>(), c = s.point(2).as<double>();
        const Vec3d e[3] = {b - a, c - b, a - c};
        int longest = 0;
        for (int i = 1; i < 3; ++i)
            if (dot(e[i], e[i]) > dot(e[longest], e[longest])) longest = i;
        const Vec3d normal = cross(e[0], e[1]);
        const double nl = std::sqrt(dot(normal, normal)), el = std::sqrt(dot(e[longest], e[longest]));
        if (!(nl > 0) || !(el > 0)) return {};  // degenerate: the box is as tight
        u = e[longest] * (1 / el), w = normal * (1 / nl), v = cross(w, u);
    } else if (s.kind == ShapeKind::capsule) {
        const Vec3d d = s.point(1).as<double>() - s.point(0).as<double>();
        const double l = std::sqrt(dot(d, d));
        if (!(l > 0)) return {};  // a sphere: the box is as tight
        u = d * (1 / l);
        const Vec3d helper = std::abs(u.x) < 0.6 ? Vec3d{1, 0, 0} : Vec3d{0, 1, 0};
        w = cross(u, helper);
        w = w * (1 / std::sqrt(dot(w, w)));
        v = cross(w, u);
    } else {
        return {};  // a sphere's tightest box is its box
    }
    // Centre and half extents along the axes, grown by a few float roundings of the scene's
    // magnitude so that the float box, its centre rounded, still contains the shape.
    const auto [u0, u1] = shape_extent(s, u);
    const auto [v0, v1] = shape_extent(s, v);
    const auto [w0, w1] = shape_extent(s, w);
    const Vec3d c = u * (0.5 * (u0 + u1)) + v * (0.5 * (v0 + v1)) + w * (0.5 * (w0 + w1));
    const Aabbd b = o.box.as<double>();
    const double m = std::max({std::abs(b.min.x), std::abs(b.min.y), std::abs(b.min.z), std::abs(b.max.x),
                               std::abs(b.max.y), std::abs(b.max.z)});
    const double grow = 4 * m * std::numeric_limits<float>::epsilon();
    // The rotation whose rows are u, v, w as a quaternion (Shepperd's method on R with columns u, v, w).
    const double r[3][3] = {{u.x, v.x, w.x}, {u.y, v.y, w.y}, {u.z, v.z, w.z}};
    double q[4];
    const double tr = r[0][0] + r[1][1] + r[2][2];
    if (tr > 0) {
        const double k = 2 * std::sqrt(1 + tr);
        q[0] = 0.25 * k, q[1] = (r[2][1] - r[1][2]) / k, q[2] = (r[0][2] - r[2][0]) / k, q[3] = (r[1][0] - r[0][1]) / k;
    } else if (r[0][0] > r[1][1] && r[0][0] > r[2][2]) {
        const double k = 2 * std::sqrt(1 + r[0][0] - r[1][1] - r[2][2]);
        q[0] = (r[2][1] - r[1][2]) / k, q[1] = 0.25 * k, q[2] = (r[0][1] + r[1][0]) / k, q[3] = (r[0][2] + r[2][0]) / k;
    } else if (r[1][1] > r[2][2]) {
        const double k = 2 * std::sqrt(1 + r[1][1] - r[0][0] - r[2][2]);
        q[0] = (r[0][2] - r[2][0]) / k, q[1] = (r[0][1] + r[1][0]) / k, q[2] = 0.25 * k, q[3] = (r[1][2] + r[2][1]) / k;
    } else {
        const double k = 2 * std::sqrt(1 + r[2][2] - r[0][0] - r[1][1]);
        q[0] = (r[1][0] - r[0][1]) / k, q[1] = (r[0][2] + r[2][0]) / k, q[2] = (r[1][2] + r[2][1]) / k, q[3] = 0.25 * k;
    }
    // The float quaternion turns the axes by up to ~1e-7 rad: grow by that over the box's reach too.
    const double reach = 0.5 * std::max({u1 - u0, v1 - v0, w1 - w0});
    const double slack = grow + 8 * reach * std::numeric_limits<float>::epsilon();
    return Shape::obb(c.as<float>(),
                      {float_above(0.5 * (u1 - u0) + slack), float_above(0.5 * (v1 - v0) + slack),
                       float_above(0.5 * (w1 - w0) + slack)},
                      {float(q[0]), float(q[1]), float(q[2]), float(q[3])});
}

}  // namespace

LeafVolume leaf_volume(const Object& o, LeafBv bv) {
    LeafVolume v;
    if (bv == LeafBv::aabb || o.shape.kind == ShapeKind::box) return v;
    if (bv == LeafBv::obb) {
        v.obb = enclosing_obb(o);
        if (v.obb.kind == ShapeKind::obb) v.bv = bv;
        return v;
    }
    v.bv = bv;
    for (int i = 0; i < diagonals(bv); ++i) {
        const auto [lo, hi] = shape_extent(o.shape, diagonal(bv, i));
        v.slab[2 * i] = float_below(lo), v.slab[2 * i + 1] = float_above(hi);
    }
    return v;
}

bool segment_hits_volume(const Segment& s, const Aabb& box, const LeafVolume& v) {
    if (v.bv == LeafBv::aabb) return true;
    if (v.bv == LeafBv::obb) return segment_hits_shape(s, v.obb);
    // The box's slabs, then each diagonal slab: the segment meets the k-DOP iff the parameter
    // intervals of all slabs overlap within [0, 1]. Conservative, so that no hit is lost: in double,
    // every slab widened by many roundings of the magnitude m of the values (a sum of up to three
    // terms ≤ m each). Rounded in float, the intervals of a zero-volume shape (each one a single t)
    // came out disjoint and the hit was dropped; an extra candidate is only tested further.
    const Vec3d p = s.p0.as<double>(), d = s.p1.as<double>() - p;
    double m = 0;
    for (int a = 0; a < 3; ++a)
        m += std::max(
            {std::abs(p[a]), std::abs(double(s.p1[a])), std::abs(double(box.min[a])), std::abs(double(box.max[a]))});
    const double slack = 64 * std::numeric_limits<double>::epsilon() * m;
    double tn = 0, tf = 1;
    // The parameters t with lo - slack <= o + t·dd <= hi + slack, intersected with [tn, tf].
    auto clip = [&](double o, double dd, double lo, double hi) {
        lo -= slack, hi += slack;
        if (dd == 0) return lo <= o && o <= hi;
        double t0 = (lo - o) / dd, t1 = (hi - o) / dd;
        if (t0 > t1) std::swap(t0, t1);
        tn = std::max(tn, t0), tf = std::min(tf, t1);
        return tn <= tf;
    };
    for (int a = 0; a < 3; ++a)
        if (!clip(p[a], d[a], box.min[a], box.max[a])) return false;
    for (int i = 0; i < diagonals(v.bv); ++i) {
        const Vec3d n = diagonal(v.bv, i);
        if (!clip(dot(n, p), dot(n, d), v.slab[2 * i], v.slab[2 * i + 1])) return false;
    }
    return true;
}

}  // namespace rcb
