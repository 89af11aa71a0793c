#pragma once
// The engine's own acceleration structure, shared by the example's main.cpp (recorded and replayed
// beside rcbench's structures), rcbench_main.cpp (the engine's rcbench: every command on it) and
// sweep_list_conformance.cpp (rcbench's conformance suite).

#include <algorithm>
#include <cstddef>
#include <limits>
#include <span>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include <accel/interface/structure.h>

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
// so nothing a ray truly hits is pruned. Updates are cheap and deferred: commit() re-sorts, by
// insertion sort by default, which costs O(n + displacement) when bodies move a little per frame.
// Its weakness: one long box early in the order lifts the running maximum for everything after it.
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
        entries_.assign(objects.begin(), objects.end());
        std::sort(entries_.begin(), entries_.end(), by_min_x);
        reindex();
    }
    void insert(const Object& o) override {
        slot_[o.uid] = entries_.size();
        entries_.push_back(o);
        dirty_ = true;
    }
    void remove(Uid uid) override {  // swap with the last entry; commit() restores the order
        auto it = slot_.find(uid);
        const std::size_t i = it->second;
        slot_.erase(it);
        if (i + 1 != entries_.size()) {
            entries_[i] = entries_.back();
            slot_[entries_[i].uid] = i;
        }
        entries_.pop_back();
        dirty_ = true;
    }
    void move(const Object& o) override {
        entries_[slot_.at(o.uid)].box = o.box;
        dirty_ = true;
    }
    void commit() override {
        if (!dirty_) return;
        if (params_.insertion_sort) {
            for (std::size_t i = 1; i < entries_.size(); ++i) {
                const Object e = entries_[i];
                std::size_t j = i;
                for (; j > 0 && by_min_x(e, entries_[j - 1]); --j) entries_[j] = entries_[j - 1];
                entries_[j] = e;
            }
        } else {
            std::sort(entries_.begin(), entries_.end(), by_min_x);
        }
        reindex();
    }

    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit) {
        const float x0 = std::min(s.p0.x, s.p1.x), x1 = std::max(s.p0.x, s.p1.x);
        // First entry whose running max x reaches x0; first entry whose min x exceeds x1.
        const auto first = std::lower_bound(running_max_x_.begin(), running_max_x_.end(), x0) - running_max_x_.begin();
        const auto last = std::upper_bound(entries_.begin(), entries_.end(), x1,
                                           [](float x, const Object& e) { return x < e.box.min.x; }) -
                          entries_.begin();
        count.traversal(2);  // the two binary searches
        const rcb::SegmentSlabs slabs(s);
        for (auto i = first; i < last; ++i) {
            count.box_tests();
            float t_near, t_far;
            if (!slabs.clip(entries_[i].box, t_near, t_far)) continue;
            count.hits();
            if (!visit(entries_[i].uid, t_near)) return;
        }
    }

    std::size_t size() const override { return entries_.size(); }
    std::size_t memory_bytes() const override {
        return entries_.capacity() * sizeof(Object) + running_max_x_.capacity() * sizeof(float) +
               slot_.bucket_count() * sizeof(void*) + slot_.size() * (sizeof(void*) + 2 * sizeof(std::size_t)) +
               sizeof(*this);
    }
    nlohmann::json stats() const override { return {{"entries", entries_.size()}}; }
    void check() const override {
        if (slot_.size() != entries_.size()) rcb::broken_invariant("sweep", "index and list differ in size");
        for (std::size_t i = 0; i < entries_.size(); ++i) {
            if (i > 0 && by_min_x(entries_[i], entries_[i - 1]))
                rcb::broken_invariant("sweep", "not sorted at entry " + std::to_string(i));
            if (slot_.at(entries_[i].uid) != i)
                rcb::broken_invariant("sweep", "stale index of uid " + std::to_string(entries_[i].uid));
            const float expected =
                std::max(i > 0 ? running_max_x_[i - 1] : entries_[i].box.max.x, entries_[i].box.max.x);
            if (running_max_x_[i] != expected)
                rcb::broken_invariant("sweep", "running max x wrong at entry " + std::to_string(i));
        }
    }

private:
    static bool by_min_x(const Object& a, const Object& b) { return a.box.min.x < b.box.min.x; }

    void reindex() {
        slot_.clear();
        running_max_x_.resize(entries_.size());
        float m = -std::numeric_limits<float>::infinity();
        for (std::size_t i = 0; i < entries_.size(); ++i) {
            slot_[entries_[i].uid] = i;
            running_max_x_[i] = m = std::max(m, entries_[i].box.max.x);
        }
        dirty_ = false;
    }

    Params params_;
    std::vector<Object> entries_;       // sorted by min x after commit
    std::vector<float> running_max_x_;  // max of max x over entries [0, i]
    std::unordered_map<Uid, std::size_t> slot_;
    bool dirty_ = false;
};

}  // namespace engine
