#include "core/accel/query_level.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/base/error.h"

namespace rcb {

ParamSpec query_param_spec() {
    ParamSpec p;
    p.name = "query";
    p.kind = ParamKind::choice;
    p.choices = {"candidates", "boxes", "shapes"};
    p.default_value = "boxes";
    p.doc =
        "query level: candidates (the traversal's output, no final box test), boxes (exact box test), shapes "
        "(narrow phase on the exact shapes)";
    p.tunable = false;
    p.recorded_when_default = false;
    return p;
}

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

TightVolume tight_volume(const Object& o, LeafBv kind) {
    TightVolume v;
    if (kind == LeafBv::aabb || o.shape.kind == ShapeKind::box) return v;
    if (kind == LeafBv::obb) {
        v.obb = enclosing_obb(o);
        if (v.obb.kind == ShapeKind::obb) v.kind = kind;
        return v;
    }
    v.kind = kind;
    for (int i = 0; i < diagonals(kind); ++i) {
        const auto [lo, hi] = shape_extent(o.shape, diagonal(kind, i));
        v.slab[2 * i] = float_below(lo), v.slab[2 * i + 1] = float_above(hi);
    }
    return v;
}

bool segment_hits_volume(const Segment& s, const Aabb& box, const TightVolume& v) {
    if (v.kind == LeafBv::aabb) return true;
    if (v.kind == LeafBv::obb) return segment_hits_shape(s, v.obb);
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
    for (int i = 0; i < diagonals(v.kind); ++i) {
        const Vec3d n = diagonal(v.kind, i);
        if (!clip(dot(n, p), dot(n, d), v.slab[2 * i], v.slab[2 * i + 1])) return false;
    }
    return true;
}

QueryLevel query_level_of(const nlohmann::json& params) {
    if (!params.is_object() || !params.contains("query")) return QueryLevel::boxes;
    const std::string q = params.at("query").get<std::string>();
    return q == "candidates" ? QueryLevel::candidates : (q == "shapes" ? QueryLevel::shapes : QueryLevel::boxes);
}

nlohmann::json own_params(const nlohmann::json& params) {
    if (!params.is_object()) return params;
    nlohmann::json own = params;
    own.erase("query");
    own.erase("leaf_bv");
    return own;
}

Contract contract_of(const nlohmann::json& params) {
    const bool tight_leaves = leaf_bv_of(params) != LeafBv::aabb;
    const bool robust = !(params.is_object() && params.contains("robust") && params.at("robust") == false);
    Contract c;
    switch (query_level_of(params)) {
        case QueryLevel::candidates:
            c = {Truth::boxes, std::nullopt};
            break;
        case QueryLevel::shapes:
            c = {Truth::shapes, Truth::shapes};
            break;
        case QueryLevel::boxes:
            c = {tight_leaves ? Truth::shapes : Truth::boxes, Truth::boxes};
            break;
    }
    if (!robust) c.lower.reset();
    return c;
}

std::unique_ptr<Structure> at_query_level(std::unique_ptr<Structure> broad, QueryLevel level, LeafBv bv,
                                          const std::string& path) {
    if (level == QueryLevel::candidates && bv != LeafBv::aabb)
        throw InputError(join_path(path, "leaf_bv") +
                         ": a tighter volume needs query boxes or shapes (candidates test no volume)");
    if (level == QueryLevel::candidates) broad->set_candidates_only(true);
    if (level == QueryLevel::shapes || bv != LeafBv::aabb)
        return std::make_unique<NarrowPhase>(std::move(broad), level == QueryLevel::shapes, bv);
    return broad;
}

NarrowPhase::NarrowPhase(std::unique_ptr<Structure> broad, bool shapes, LeafBv bv)
    : broad_(std::move(broad)), shapes_(shapes), bv_(bv) {}

void NarrowPhase::set(const Object& o) {
    // Dense while uids stay below four times the object count (with a floor for small scenes).
    const std::size_t dense_limit = 4 * (broad_->size() + 1024);
    if (o.uid >= dense_.size() && o.uid < dense_limit) {
        dense_.resize(std::size_t(o.uid) + 1);
        for (auto it = sparse_.begin(); it != sparse_.end();)  // uids the table now covers move into it
            if (it->first < dense_.size()) {
                dense_[it->first] = it->second;
                it = sparse_.erase(it);
            } else {
                ++it;
            }
    }
    Entry& e = o.uid < dense_.size() ? dense_[o.uid] : sparse_[o.uid];
    if (e.live) shaped_ -= e.shape.kind != ShapeKind::box;
    live_ += !e.live;
    shaped_ += o.shape.kind != ShapeKind::box;
    std::uint32_t volume = e.volume;
    if (bv_ != LeafBv::aabb) {
        TightVolume v = tight_volume(o, bv_);
        if (v.kind == LeafBv::aabb && volume != kNoVolume) {
            free_volumes_.push_back(volume);
            volume = kNoVolume;
        } else if (v.kind != LeafBv::aabb) {
            if (volume == kNoVolume) {
                if (free_volumes_.empty()) {
                    volume = std::uint32_t(volumes_.size());
                    volumes_.emplace_back();
                } else {
                    volume = free_volumes_.back();
                    free_volumes_.pop_back();
                }
            }
            volumes_[volume] = v;
        }
    }
    e = {o.box, o.shape, true, volume};
}

void NarrowPhase::erase(Uid uid) {
    const Entry& e = entry(uid);
    shaped_ -= e.shape.kind != ShapeKind::box;
    --live_;
    if (e.volume != kNoVolume) free_volumes_.push_back(e.volume);
    if (uid < dense_.size())
        dense_[uid] = Entry{};
    else
        sparse_.erase(uid);
}

void NarrowPhase::build(std::span<const Object> objects) {
    broad_->build(objects);
    dense_.clear();
    sparse_.clear();
    volumes_.clear();
    free_volumes_.clear();
    live_ = shaped_ = 0;
    for (const Object& o : objects) set(o);
}

void NarrowPhase::insert(const Object& object) {
    broad_->insert(object);
    set(object);
}

void NarrowPhase::remove(Uid uid) {
    broad_->remove(uid);
    erase(uid);
}

void NarrowPhase::move(const Object& object) {
    broad_->move(object);
    set(object);
}

template <class Tally>
bool NarrowPhase::survives(const Segment& s, const Entry& e, float* t, Tally&& tally) const {
    if (e.shape.kind == ShapeKind::box) return true;  // its box hit is the hit
    if (e.volume != kNoVolume && !segment_hits_volume(s, e.box, volumes_[e.volume])) return false;
    if (!shapes_) return true;
    const bool hit = segment_hits_shape(s, e.shape, t);
    tally(hit);
    return hit;
}

template <class Tally>
void NarrowPhase::filter(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& hits,
                         Tally&& tally) const {
    // In place: a ray's kept hits move down over the dropped ones; closest and any keep one.
    std::uint32_t write = 0, begin = 0;
    for (std::size_t r = 0; r < rays.size(); ++r) {
        const std::uint32_t end = hits.offsets[r + 1];
        const QueryKind kind = kinds.empty() ? QueryKind::all : kinds[r];
        if (kind == QueryKind::closest) {
            // The nearest entry into a shape: a box's entry says nothing of its shape's.
            const SegmentSlabs slabs(rays[r]);
            ClosestHit closest;
            for (std::uint32_t i = begin; i < end; ++i) {
                const Entry& e = entry(hits.uids[i]);
                float t = 0, t_far;
                if (slabs.clip(e.box, t, t_far) && survives(rays[r], e, &t, tally)) closest(hits.uids[i], t);
            }
            if (closest.found) hits.uids[write++] = closest.uid;
        } else {
            for (std::uint32_t i = begin; i < end; ++i) {
                const Uid uid = hits.uids[i];
                if (!survives(rays[r], entry(uid), nullptr, tally)) continue;
                hits.uids[write++] = uid;
                if (kind == QueryKind::any) break;
            }
        }
        begin = end;
        hits.offsets[r + 1] = write;
    }
    hits.uids.resize(write);
}

void NarrowPhase::cast(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out) {
    // Boxes only: every box hit is a hit, and the structure answers each kind itself.
    if (shaped_ == 0) return broad_->cast(rays, kinds, out);
    broad_->cast(rays, {}, out);
    filter(rays, kinds, out, [](bool) {});
}

void NarrowPhase::cast_counted(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out,
                               Counters& counters) {
    if (shaped_ == 0) return broad_->cast_counted(rays, kinds, out, counters);
    broad_->cast_counted(rays, {}, out, counters);
    filter(rays, kinds, out, [&](bool hit) {
        ++counters.n_ro;
        counters.n_ro_hits += hit;
    });
}

std::optional<Hit> NarrowPhase::cast_closest(const Segment& segment) {
    // Every box hit, then the nearest entry into a shape: a box's entry says nothing of its shape's.
    broad_->cast(std::span<const Segment>(&segment, 1), scratch_);
    const SegmentSlabs slabs(segment);
    ClosestHit closest;
    for (Uid uid : scratch_.of(0)) {
        const Entry& e = entry(uid);
        float t = 0, t_far;
        if (slabs.clip(e.box, t, t_far) && survives(segment, e, &t, [](bool) {})) closest(uid, t);
    }
    if (!closest.found) return std::nullopt;
    return Hit{closest.uid, closest.t_limit};
}

bool NarrowPhase::cast_any(const Segment& segment) {
    broad_->cast(std::span<const Segment>(&segment, 1), scratch_);
    for (Uid uid : scratch_.of(0))
        if (survives(segment, entry(uid), nullptr, [](bool) {})) return true;
    return false;
}

std::size_t NarrowPhase::memory_bytes() const {
    return broad_->memory_bytes() + dense_.capacity() * sizeof(Entry) +
           sparse_.size() * (sizeof(Entry) + sizeof(Uid) + 2 * sizeof(void*)) +
           volumes_.capacity() * sizeof(TightVolume) + free_volumes_.capacity() * sizeof(std::uint32_t);
}

void NarrowPhase::validate() const {
    broad_->validate();
    std::size_t live = sparse_.size(), shaped = 0;
    for (const Entry& e : dense_) live += e.live;
    for (const Entry& e : dense_) shaped += e.live && e.shape.kind != ShapeKind::box;
    for (const auto& [uid, e] : sparse_) shaped += e.shape.kind != ShapeKind::box;
    if (live != live_ || shaped != shaped_) broken_invariant("narrow phase", "object counts differ from its table");
    if (live != broad_->size()) broken_invariant("narrow phase", "holds another object count than its structure");
}

}  // namespace rcb
