#pragma once
// The engine's own acceleration structure, shared by the example's main.cpp (recorded and replayed
// beside rcbench's structures), rcbench_main.cpp (the engine's rcbench: every command on it) and
// sweep_list_conformance.cpp (rcbench's conformance suite).

#include <algorithm>
#include <cstddef>
#include <span>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

#include <accel/interface/structure.h>
#include <core/base/heap_bytes.h>

namespace engine {

using rcb::Aabb;
using rcb::Object;
using rcb::Segment;
using rcb::Uid;

/// SweepList's line in the registry (`rcbench structures`), for every program that registers it.
inline constexpr const char* kSweepListSummary = "the engine's sweep list: sorted by min x, running max x, slab tests";

// (b) The engine's structure: objects sorted by their box's min x (a one-axis sweep list, as in
// sweep-and-prune broad phases), with the running maximum of max x along that order. A ray whose
// x-range is [x0, x1] can only hit entries with min x <= x1 (a prefix, found by binary search) and
// max x >= x0 (none before the first entry whose running maximum reaches x0, found likewise); the
// entries in between get the exact slab test. Both bounds are plain comparisons of coordinates,
// so nothing a ray truly hits is pruned. Updates are cheap and deferred: a change only sets the
// uid's box; commit() drops the removed entries, refreshes the moved ones and re-sorts, by insertion
// sort by default, which costs O(n + displacement) when bodies move a little per frame (the
// simulator commits after each frame's changes, and a uid changes at most once in a frame).
// Its weakness: one long box early in the order lifts the running maximum for everything after it.
// 60 lines of code: the class without blank lines and comments.
class SweepList : public rcb::StructureBase<SweepList> {
public:
    struct Params {
        bool insertion_sort = true;
        static constexpr auto fields() {
            return std::tuple{rcb::Field{"insertion_sort", &Params::insertion_sort, 0, 1,
                                         "re-sort by insertion sort (adaptive) instead of std::sort"}};
        }
    };
    explicit SweepList(const Params& p) : params_(p) {}

    void build(std::span<const Object> objects) override {
        boxes_.clear(), entries_.clear();
        for (const Object& o : objects) insert(o);
        commit();
    }
    // Changes go to the boxes by uid; commit() brings the list up to date (drops, updates, re-sorts).
    void insert(const Object& o) override { boxes_[o.uid] = o.box, entries_.push_back(o), dirty_ = true; }
    void remove(Uid uid) override { boxes_.erase(uid), dirty_ = true; }
    void move(const Object& o) override { boxes_.at(o.uid) = o.box, dirty_ = true; }
    void commit() override {
        if (!std::exchange(dirty_, false)) return;
        std::erase_if(entries_, [&](Object& e) { return !boxes_.count(e.uid) || (e.box = boxes_.at(e.uid), false); });
        if (!params_.insertion_sort) std::ranges::sort(entries_, {}, min_x);
        for (auto e = entries_.begin(); params_.insertion_sort && e != entries_.end(); ++e)  // O(n + displacement)
            for (auto j = e; j != entries_.begin() && min_x(*j) < min_x(*(j - 1)); --j) std::iter_swap(j, j - 1);
        running_max_x_.resize(entries_.size());
        for (std::size_t i = 0; i < entries_.size(); ++i)
            running_max_x_[i] = std::max(i ? running_max_x_[i - 1] : entries_[i].box.max.x, entries_[i].box.max.x);
    }

    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit) {
        // Entries whose running max x reaches the ray's min x and whose min x is at most its max x.
        const auto first = std::ranges::lower_bound(running_max_x_, std::min(s.p0.x, s.p1.x)) - running_max_x_.begin();
        const auto last = std::ranges::upper_bound(entries_, std::max(s.p0.x, s.p1.x), {}, min_x) - entries_.begin();
        count.traversal(2);  // the two binary searches
        const rcb::SegmentSlabs slabs(s);
        float t_near, t_far;
        for (auto i = first; i < last; ++i) {
            count.box_tests();
            if (!slabs.clip(entries_[i].box, t_near, t_far)) continue;
            count.hits();
            if (!visit(entries_[i].uid, t_near)) return;
        }
    }

    std::size_t size() const override { return entries_.size(); }
    std::size_t memory_bytes() const override {
        return sizeof(*this) + rcb::heap_bytes(entries_, running_max_x_, boxes_);
    }
    void check() const override {  // a copy brought up to date afresh (by insertion sort: stable) equals this one
        SweepList fresh(Params{true});
        fresh.build(entries_);
        if (std::tie(fresh.boxes_, fresh.entries_, fresh.running_max_x_) != std::tie(boxes_, entries_, running_max_x_))
            rcb::broken_invariant("sweep", "not as commit() leaves it (up to date, sorted by min x, running max)");
    }

private:
    static float min_x(const Object& o) { return o.box.min.x; }

    Params params_;
    std::vector<Object> entries_;       // sorted by min x after commit()
    std::vector<float> running_max_x_;  // max of max x over entries [0, i]
    std::unordered_map<Uid, rcb::Aabb> boxes_;
    bool dirty_ = false;
};

}  // namespace engine
