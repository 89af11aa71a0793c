#include "core/truth/ground_truth.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <tuple>

namespace rcb {
namespace {

double magnitude_of(const Vec3d& a, const Vec3d& b) {
    return std::max({std::abs(a.x), std::abs(a.y), std::abs(a.z), std::abs(b.x), std::abs(b.y), std::abs(b.z)});
}

/// Box shrunk by eps per side; an axis thinner than 2·eps collapses to its mid-plane.
Aabbd shrunk(const Aabbd& b, double eps) {
    Aabbd s;
    for (int a = 0; a < 3; ++a) {
        s.min[a] = b.min[a] + eps;
        s.max[a] = b.max[a] - eps;
        if (s.min[a] > s.max[a]) s.min[a] = s.max[a] = 0.5 * (b.min[a] + b.max[a]);
    }
    return s;
}

Aabbd grown(const Aabbd& b, double eps) { return {b.min - Vec3d{eps, eps, eps}, b.max + Vec3d{eps, eps, eps}}; }

/// ε in segment parameter units: moving an end point by ε (L∞) changes t by ε / max|d_a|.
double t_tolerance(const SegmentSlabsd& slabs, double eps) {
    const double longest = 1.0 / std::min({std::abs(slabs.inv.x), std::abs(slabs.inv.y), std::abs(slabs.inv.z)});
    if (eps == 0) return 0;
    return longest > 0 ? eps / longest : std::numeric_limits<double>::infinity();
}

constexpr double kInfinity = std::numeric_limits<double>::infinity();

/// A box contact and where the segment may enter the box under the moves of ε: no earlier than
/// t_early (the lengthened segment into the grown box), and, for a must-hit, no later than t_late
/// (the shortened segment into the shrunk box, plus the parameter's own move); +∞ when unknown.
struct BoxContact {
    Contact contact = Contact::miss;
    double t_early = kInfinity, t_late = kInfinity;
};

BoxContact classify_box(const SegmentSlabsd& slabs, const Aabbd& box, double eps) {
    const double dt = t_tolerance(slabs, eps);
    double tn, tf;
    if (!slabs.clip(grown(box, eps), tn, tf, -dt, 1 + dt)) return {};
    const double early = tn;
    // Shortened by dt at both ends; a segment shorter than 2ε shrinks to its midpoint.
    const double t0 = std::min(dt, 0.5), t1 = std::max(1 - dt, 0.5);
    if (!slabs.clip(shrunk(box, eps), tn, tf, t0, t1)) return {Contact::touch, early, kInfinity};
    return {Contact::hit, early, tn + dt};
}

Contact classify_prepared(const SegmentSlabsd& slabs, const Aabbd& box, double eps) {
    return classify_box(slabs, box, eps).contact;
}

constexpr std::uint32_t kNoShape = ~std::uint32_t(0);

double length(const Vec3d& v) { return std::sqrt(dot(v, v)); }

/// The sign of det[r1; r2; r3] if no move of each row by up to `delta` (Euclidean) can change it,
/// else 0. By multilinearity and Hadamard's inequality the determinant moves by at most
/// (n1 + δ)(n2 + δ)(n3 + δ) − n1·n2·n3; the last term covers double's own rounding.
int certain_sign(const Vec3d& r1, const Vec3d& r2, const Vec3d& r3, double delta) {
    const double v = dot(r1, cross(r2, r3));
    const double n1 = length(r1), n2 = length(r2), n3 = length(r3);
    const double slack = (n1 + delta) * (n2 + delta) * (n3 + delta) - n1 * n2 * n3 + 1e-12 * n1 * n2 * n3;
    return v > slack ? 1 : (v < -slack ? -1 : 0);
}

/// The segment crosses the triangle iff its ends are not strictly on one side of the plane and the
/// three edges pass the segment's line on one side (Plücker signs). Certain signs decide hit and
/// miss; anything else (ends on the plane, the line through an edge, a segment in the plane, a
/// degenerate triangle crossed edge-on) is a touch. Points move by ε per axis, √3·ε in length, so
/// a difference of two points by 2√3·ε.
Contact classify_triangle(const Segmentd& s, const Shape& tri, double eps) {
    const double delta = 2 * std::sqrt(3.0) * eps;
    const Vec3d a = tri.point(0).as<double>(), b = tri.point(1).as<double>(), c = tri.point(2).as<double>();
    const Vec3d d = s.delta();
    const int o0 = certain_sign(b - a, c - a, s.p0 - a, delta), o1 = certain_sign(b - a, c - a, s.p1 - a, delta);
    if (o0 != 0 && o0 == o1) return Contact::miss;
    const int e[3] = {certain_sign(d, a - s.p0, b - s.p0, delta), certain_sign(d, b - s.p0, c - s.p0, delta),
                      certain_sign(d, c - s.p0, a - s.p0, delta)};
    const bool pos = e[0] > 0 || e[1] > 0 || e[2] > 0, neg = e[0] < 0 || e[1] < 0 || e[2] < 0;
    if (pos && neg) return Contact::miss;
    const bool inside = e[0] != 0 && e[1] != 0 && e[2] != 0;  // then all of one sign
    return inside && o0 != 0 && o1 == -o0 ? Contact::hit : Contact::touch;
}

/// The box test in the obb's frame: a rotation keeps lengths, so moves of ε per world axis are
/// moves of at most √3·ε per local axis.
Contact classify_obb(const Segmentd& s, const Shape& box, double eps) {
    const std::array<Vec3d, 3> axis = obb_axes<double>(box);
    const Vec3d c = box.point(0).as<double>(), h = box.point(1).as<double>();
    auto local = [&](const Vec3d& p) {
        const Vec3d l = p - c;
        return Vec3d{dot(l, axis[0]), dot(l, axis[1]), dot(l, axis[2])};
    };
    const Segmentd ls{local(s.p0), local(s.p1)};
    return classify_prepared(SegmentSlabsd(ls), Aabbd{{-h.x, -h.y, -h.z}, h}, std::sqrt(3.0) * eps);
}

/// Spheres and capsules: the distance from the segment to the centre point or axis segment,
/// which moves by at most 2√3·ε.
Contact classify_round(const Segmentd& s, const Shape& shape, double eps) {
    const double r = shape.radius();
    const double dist = std::sqrt(closest_points(s, shape.core<double>()).distance2);
    const double delta = 2 * std::sqrt(3.0) * eps;
    if (dist > r + delta) return Contact::miss;
    return dist < r - delta ? Contact::hit : Contact::touch;
}

Contact classify_shape_eps(const Segmentd& s, const Shape& shape, double eps) {
    switch (shape.kind) {
        case ShapeKind::triangle:
            return classify_triangle(s, shape, eps);
        case ShapeKind::obb:
            return classify_obb(s, shape, eps);
        case ShapeKind::sphere:
        case ShapeKind::capsule:
            return classify_round(s, shape, eps);
        case ShapeKind::box:
            break;
    }
    throw std::logic_error("classify_shape_contact: a box has no shape test");
}

}  // namespace

Contact classify_contact(const Segmentd& s, const Aabbd& box) {
    double eps = kRelativeTolerance * std::max(magnitude_of(s.p0, s.p1), magnitude_of(box.min, box.max));
    return classify_prepared(SegmentSlabsd(s), box, eps);
}

Contact classify_shape_contact(const Segmentd& s, const Shape& shape) {
    const Aabbd box = shape_bounds(shape).as<double>();
    const double eps = kRelativeTolerance * std::max(magnitude_of(s.p0, s.p1), magnitude_of(box.min, box.max));
    if (classify_prepared(SegmentSlabsd(s), box, eps) == Contact::miss) return Contact::miss;
    return classify_shape_eps(s, shape, eps);
}

GroundTruth::GroundTruth(const std::vector<Object>& objects) {
    const std::size_t n = objects.size();
    for (int a = 0; a < 3; ++a) {
        min_[a].resize(n);
        max_[a].resize(n);
    }
    magnitude_.resize(n);
    uids_.resize(n);
    shape_of_.assign(n, kNoShape);
    for (std::size_t i = 0; i < n; ++i) {
        if (objects[i].shape.kind != ShapeKind::box) {
            shape_of_[i] = std::uint32_t(shaped_.size());
            shaped_.push_back(objects[i].shape);
        }
        const Aabbd b = objects[i].box.as<double>();
        for (int a = 0; a < 3; ++a) {
            min_[a][i] = b.min[a];
            max_[a][i] = b.max[a];
        }
        magnitude_[i] = magnitude_of(b.min, b.max);
        uids_[i] = objects[i].uid;
    }
}

void GroundTruth::classify(const Segment& segment, std::vector<Uid>& must, std::vector<Uid>& touch, Truth level) const {
    must.clear();
    touch.clear();
    std::vector<Contacts> found;
    contacts(segment, found);
    for (const Contacts& c : found) {
        const Contact k = level == Truth::boxes ? c.box : c.shape;
        if (k == Contact::hit)
            must.push_back(c.uid);
        else if (k == Contact::touch)
            touch.push_back(c.uid);
    }
}

void GroundTruth::contacts(const Segment& segment, std::vector<Contacts>& out) const {
    out.clear();
    const Segmentd s{segment.p0.as<double>(), segment.p1.as<double>()};
    const SegmentSlabsd slabs(s);
    const double seg_mag = magnitude_of(s.p0, s.p1);
    const double longest = 1.0 / std::min({std::abs(slabs.inv.x), std::abs(slabs.inv.y), std::abs(slabs.inv.z)});
    const double t_per_eps = longest > 0 ? 1.0 / longest : std::numeric_limits<double>::infinity();
    const std::size_t n = uids_.size();
    // Cheap filter first, vectorisable: the segment against every box grown by its ε.
    constexpr std::size_t kBlock = 1024;
    std::uint8_t candidate[kBlock];
    for (std::size_t begin = 0; begin < n; begin += kBlock) {
        const std::size_t end = std::min(n, begin + kBlock);
        for (std::size_t i = begin; i < end; ++i) {
            const double eps = kRelativeTolerance * std::max(seg_mag, magnitude_[i]);
            // The segment lengthened by ε at both ends (see classify_prepared).
            const double dt = eps > 0 ? eps * t_per_eps : 0.0;
            double tn = -dt, tf = 1.0 + dt;
            for (int a = 0; a < 3; ++a) {
                const double near = slabs.near_is_max[a] ? max_[a][i] + eps : min_[a][i] - eps;
                const double far = slabs.near_is_max[a] ? min_[a][i] - eps : max_[a][i] + eps;
                const double lo = (near - slabs.origin[a]) * slabs.inv[a];
                const double hi = (far - slabs.origin[a]) * slabs.inv[a];
                tn = max_ignoring_nan(lo, tn);
                tf = min_ignoring_nan(hi, tf);
            }
            candidate[i - begin] = tn <= tf;
        }
        for (std::size_t i = begin; i < end; ++i) {
            if (!candidate[i - begin]) continue;
            const double eps = kRelativeTolerance * std::max(seg_mag, magnitude_[i]);
            const Aabbd box{{min_[0][i], min_[1][i], min_[2][i]}, {max_[0][i], max_[1][i], max_[2][i]}};
            const BoxContact c = classify_box(slabs, box, eps);
            if (c.contact == Contact::miss) continue;
            const bool shaped = shape_of_[i] != kNoShape;
            const Contact shape = shaped ? classify_shape_eps(s, shaped_[shape_of_[i]], eps) : c.contact;
            out.push_back({uids_[i], c.contact, shape, shaped, c.t_early, c.t_late});
        }
    }
    std::sort(out.begin(), out.end(), [](const Contacts& a, const Contacts& b) { return a.uid < b.uid; });
}

std::optional<TrueHit> GroundTruth::closest(const Segment& segment) const {
    const SegmentSlabsd slabs(Segmentd{segment.p0.as<double>(), segment.p1.as<double>()});
    std::optional<TrueHit> best;
    for (std::size_t i = 0; i < uids_.size(); ++i) {
        double tn, tf;
        const Aabbd box{{min_[0][i], min_[1][i], min_[2][i]}, {max_[0][i], max_[1][i], max_[2][i]}};
        if (!slabs.clip(box, tn, tf)) continue;
        if (!best || tn < best->t || (tn == best->t && uids_[i] < best->uid)) best = TrueHit{uids_[i], tn};
    }
    return best;
}

bool GroundTruth::any(const Segment& segment) const {
    const SegmentSlabsd slabs(Segmentd{segment.p0.as<double>(), segment.p1.as<double>()});
    for (std::size_t i = 0; i < uids_.size(); ++i)
        if (slabs.hits(Aabbd{{min_[0][i], min_[1][i], min_[2][i]}, {max_[0][i], max_[1][i], max_[2][i]}})) return true;
    return false;
}

namespace {

Contact at_level(Contact box, Contact shape, Truth t) { return t == Truth::boxes ? box : shape; }

/// One all-hits ray: `reported` sorted, duplicates counted, against the sorted contacts.
template <class Found, class Note>
void verify_all(const Found& found, std::vector<Uid>& reported, const Contract& contract, Verification& v,
                Note&& note) {
    for (std::size_t i = 1; i < reported.size(); ++i)
        if (reported[i] == reported[i - 1]) {
            ++v.duplicate;
            note(reported[i], Discrepancy::duplicate);
        }
    reported.erase(std::unique(reported.begin(), reported.end()), reported.end());
    v.returned += reported.size();
    // One uid of the union at a time: reported or not, its contacts or none (a clear miss).
    std::size_t i = 0, j = 0;
    while (i < reported.size() || j < found.size()) {
        const bool has_entry = j < found.size() && (i == reported.size() || found[j].uid <= reported[i]);
        const bool is_reported = i < reported.size() && (j == found.size() || reported[i] <= found[j].uid);
        const Uid uid = is_reported ? reported[i] : found[j].uid;
        const Contact box = has_entry ? found[j].box : Contact::miss, shape = has_entry ? found[j].shape : box;
        if (!is_reported && contract.lower && at_level(box, shape, *contract.lower) == Contact::hit) {
            ++v.missed;
            note(uid, Discrepancy::missed);
        }
        if (is_reported && contract.upper && at_level(box, shape, *contract.upper) == Contact::miss) {
            ++v.extra;
            note(uid, Discrepancy::extra);
        }
        if (is_reported && shape != Contact::miss) ++v.correct;
        if (shape == Contact::hit || (is_reported && shape == Contact::touch)) ++v.relevant;
        if (is_reported) ++i;
        if (has_entry) ++j;
    }
}

/// One closest or any ray (docs/accuracy.md, "Query kinds"): at most one uid; none only when
/// nothing must be hit; the one reported not clearly missed; for closest, not clearly behind the
/// latest entry of an object that must be hit (entries of shapes are bounded by their boxes').
template <class Found, class Note>
void verify_one(const Found& found, std::span<const Uid> reported, QueryKind kind, const Contract& contract,
                Verification& v, Note&& note) {
    for (std::size_t i = 1; i < reported.size(); ++i) {
        ++v.extra;
        note(reported[i], Discrepancy::extra);
    }
    // The must-hit object that must be entered first (for any: the first must-hit, by uid).
    const typename Found::value_type* first = nullptr;
    double first_late = kInfinity;
    bool shape_hit = false;
    for (const auto& c : found) {
        shape_hit = shape_hit || c.shape == Contact::hit;
        if (!contract.lower || at_level(c.box, c.shape, *contract.lower) != Contact::hit) continue;
        const double late = *contract.lower == Truth::shapes && c.shaped ? kInfinity : c.t_late;
        if (!first || late < first_late) first = &c, first_late = late;
    }
    if (reported.empty()) {
        if (first) {
            ++v.missed;
            note(first->uid, Discrepancy::missed);
        }
        v.relevant += shape_hit;
        return;
    }
    const Uid uid = reported[0];
    auto it = std::lower_bound(found.begin(), found.end(), uid, [](const auto& c, Uid u) { return c.uid < u; });
    const bool has_entry = it != found.end() && it->uid == uid;
    const Contact box = has_entry ? it->box : Contact::miss, shape = has_entry ? it->shape : box;
    ++v.returned;
    if (contract.upper && at_level(box, shape, *contract.upper) == Contact::miss) {
        ++v.extra;
        note(uid, Discrepancy::extra);
    } else if (kind == QueryKind::closest && first && contract.upper && it->t_early > first_late) {
        ++v.missed;  // the nearest was missed: `uid` lies clearly behind it
        note(first->uid, Discrepancy::missed);
    }
    if (shape != Contact::miss) ++v.correct;
    v.relevant += shape_hit || shape == Contact::touch;
}

}  // namespace

Verification GroundTruth::verify(std::span<const Segment> rays, const HitLists& hits, const Contract& contract,
                                 std::size_t max_examples) const {
    return verify(rays, {}, hits, contract, max_examples);
}

Verification GroundTruth::verify(std::span<const Segment> rays, std::span<const QueryKind> kinds, const HitLists& hits,
                                 const Contract& contract, std::size_t max_examples) const {
    Verification total;
    std::mutex merge;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays.size(), 8),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                          Verification local;
                          std::vector<Contacts> found;
                          std::vector<Uid> reported;
                          for (std::size_t r = range.begin(); r != range.end(); ++r) {
                              auto note = [&](Uid uid, Discrepancy::Kind kind) {
                                  if (local.examples.size() < max_examples)
                                      local.examples.push_back({static_cast<std::uint32_t>(r), uid, kind});
                              };
                              contacts(rays[r], found);
                              const QueryKind kind = kinds.empty() ? QueryKind::all : kinds[r];
                              if (kind != QueryKind::all) {
                                  verify_one(found, hits.of(r), kind, contract, local, note);
                                  continue;
                              }
                              auto got = hits.of(r);
                              reported.assign(got.begin(), got.end());
                              std::sort(reported.begin(), reported.end());
                              verify_all(found, reported, contract, local, note);
                          }
                          std::lock_guard<std::mutex> lock(merge);
                          total.missed += local.missed;
                          total.extra += local.extra;
                          total.duplicate += local.duplicate;
                          total.returned += local.returned;
                          total.correct += local.correct;
                          total.relevant += local.relevant;
                          total.examples.insert(total.examples.end(), local.examples.begin(), local.examples.end());
                      });
    // Every chunk kept its first examples; keep the first of all, so the examples do not depend
    // on how the rays were split among threads.
    std::sort(total.examples.begin(), total.examples.end(), [](const Discrepancy& a, const Discrepancy& b) {
        return std::tie(a.ray, a.uid) < std::tie(b.ray, b.uid);
    });
    if (total.examples.size() > max_examples) total.examples.resize(max_examples);
    return total;
}

}  // namespace rcb
