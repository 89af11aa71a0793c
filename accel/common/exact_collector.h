#pragma once
/// The peers' collector. A library's broad phase (Embree's BVH, Bullet's btDbvt, ODE's spaces) is
/// given padded boxes, so it names every box the segment touches, and some more, as candidates;
/// `offer(slot)` decides each with rcb's exact slab test on the unpadded box, counts the test and
/// the hit and hands the hit to the query's visitor (hit_policy.h). Hits, t and the touching rule
/// then equal every rcb structure's (docs/structures.md, "The peers"). `traverse_or_scan` runs a
/// library's query with one collector and answers the segments the library cannot take with the
/// exact scan (box_scan.h).

#include <cmath>
#include <cstdint>
#include <span>
#include <type_traits>

#include "accel/common/box_scan.h"
#include "accel/common/slot_boxes.h"
#include "accel/interface/hit_policy.h"
#include "core/base/geometry.h"

namespace rcb {

/// The any-hit visitor (hit_policy.h), which ends the query at its first hit: a library with an
/// occlusion query (Embree's rtcOccluded1) answers it with that.
template <class Visit>
concept StopsAtFirstHit = std::is_same_v<std::remove_cvref_t<Visit>, AnyHit>;

class ExactCollector {
public:
    /// What one offer came to: the candidate missed, hit, or the visitor wants no more hits (also
    /// every offer after that: a library that cannot be stopped mid-query gets no further tests).
    enum class Offer : std::uint8_t { miss, hit, stop };

    /// At the candidate level (counters.h) every offered slot is yielded untested, at t = 0.
    template <class Visit>
    ExactCollector(const SegmentSlabs& slabs, const SlotBoxes& objects, Visit& visit, bool candidates)
        : slabs_(&slabs),
          objects_(&objects),
          visit_(&visit),
          on_hit_([](void* v, Uid uid, float t) { return bool((*static_cast<Visit*>(v))(uid, t)); }),
          candidates_(candidates) {
        if constexpr (HasTLimit<Visit>)
            limit_of_ = [](const void* v) { return float(static_cast<const Visit*>(v)->t_limit); };
    }

    Offer offer(std::uint32_t slot) {
        if (stopped_) return Offer::stop;
        float tn = 0, tf;
        if (!candidates_) {
            ++tests_;
            if (!slabs_->clip(objects_->box(slot), tn, tf)) return Offer::miss;
        }
        ++hits_;
        if (on_hit_(visit_, objects_->uid(slot), tn)) return Offer::hit;
        stopped_ = true;
        return Offer::stop;
    }

    /// Whether the visitor has a t_limit (closest hit), and its value: nothing entered beyond it
    /// can change the answer, so a library that can clip its ray may clip it there.
    bool has_limit() const { return limit_of_ != nullptr; }
    float limit() const { return limit_of_(visit_); }

    /// Box tests the library makes itself and reports (ODE's hash space scans every geom's AABB).
    void add_tests(std::uint64_t n) { tests_ += n; }
    std::uint64_t tests() const { return tests_; }
    std::uint64_t hits() const { return hits_; }
    bool stopped() const { return stopped_; }

private:
    const SegmentSlabs* slabs_;
    const SlotBoxes* objects_;
    void* visit_;
    bool (*on_hit_)(void* visit, Uid uid, float t);
    float (*limit_of_)(const void* visit) = nullptr;
    bool candidates_;
    std::uint64_t tests_ = 0;
    std::uint64_t hits_ = 0;
    bool stopped_ = false;
};

/// Whether a library may take the segment: its ends finite and within `far` of the origin on every
/// axis (the peers use kFarFactor × their scale: beyond it the library's float ray set-up may round
/// by more than the padding covers).
inline bool within_reach(const Segment& s, float far) {
    if (!is_finite(s.p0) || !is_finite(s.p1)) return false;
    for (int a = 0; a < 3; ++a)
        if (std::abs(s.p0[a]) > far || std::abs(s.p1[a]) > far) return false;
    return true;
}

/// A peer's traversal: `library(collector)` runs the library's query, offering each candidate to
/// the collector, or returns false for a segment it cannot take, which the exact scan of `objects`
/// answers instead. Counters: N_RB = the collector's tests (or the scan's), N_TP its hits.
template <class Count, class Visit, class Library>
void traverse_or_scan(const Segment& s, const SlotBoxes& objects, Count& count, Visit& visit, Library&& library) {
    if (objects.empty()) return;
    const SegmentSlabs slabs(s);
    ExactCollector collector(slabs, objects, visit, Count::candidates);
    if (!library(collector)) {
        scan_boxes(slabs, std::span<const Aabb>(objects.layout().all()), std::span<const Uid>(objects.uids()), count,
                   visit);
        return;
    }
    count.box_tests(collector.tests());
    count.hits(collector.hits());
}

}  // namespace rcb
