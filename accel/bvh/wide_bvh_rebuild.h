#pragma once
/// The wide BVH's progressive rebuild (wide_bvh.h), as PhysX's dynamic pruner and Jolt's quad tree
/// do: a next tree is gathered from the live objects and built (wide_bvh_build.h) a budget of work
/// per commit, the changes meanwhile are logged and replayed into it, and the trees swap; the live
/// tree answers throughout. wide_bvh_rebuild.cpp has the details.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <unordered_set>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/scene/scene.h"

namespace rcb {

class WideBvh;

/// The progressive rebuild of a live tree: the next tree, the log of changes to replay into it,
/// and the work per commit. The tree passed to each call is the live one (its owner).
class WideBvhRebuild {
public:
    /// Where a rebuild is: gathering the live objects, building the next tree from them, replaying
    /// the changes logged since the gathering began, or freeing the replaced tree.
    enum class Phase : std::uint8_t { idle, gather, build, replay, dispose };
    // Work units (the build's: an item binned, bounded or partitioned, an object written to a leaf)
    // of a replayed uid (two lookups, then a lane write, an insert or a remove in the next tree) and
    // of an index entry freed, from their times against the build's.
    static constexpr std::uint64_t kReplayUnits = 16, kDisposeUnits = 4;

    WideBvhRebuild();
    ~WideBvhRebuild();  // where WideBvh is complete (the next tree)

    Phase phase() const { return phase_; }
    /// Work units of the last commit.
    std::uint64_t work() const { return work_; }
    /// Drops a rebuild in progress (build(): new contents replace everything).
    void reset();
    /// After a build of the live tree from `objects` objects in `build_work` units: until a
    /// rebuild has measured it, the build's units plus about one per object for the gathering
    /// and one for the replay.
    void estimate(std::uint64_t build_work, std::size_t objects);
    /// Every commit first: no budget and no work yet.
    void open_commit() { budget_ = work_ = 0; }
    /// A commit that follows changes (`changes` of them, `weighted` as the trigger counts
    /// them): starts a rebuild when one is due, and spends the budget they earn on the one in
    /// progress. The budget follows the changes themselves, not their weight: each of them is
    /// logged and replayed alike, so a rebuild's length in commits stays bounded by them.
    void commit(WideBvh& live, std::uint64_t changes, double weighted);
    /// A change to the live tree while a rebuild gathers, builds or replays: the uid is
    /// replayed into the next tree before the swap (and skipped by the gathering, if not yet
    /// gathered).
    void log_change(Uid uid) {
        if (phase_ == Phase::idle || phase_ == Phase::dispose) return;
        log_.push_back(uid);
        if (phase_ == Phase::gather) gather_skip_.insert(uid);
    }
    /// An object of the live tree moved to another lane (a leaf split, a remove filling its
    /// hole): only the gathering cares, which could see it twice or not at all.
    void log_relocation(Uid uid) {
        if (phase_ == Phase::gather) log_change(uid);
    }
    void add_stats(nlohmann::json& stats) const;
    std::size_t memory_bytes() const;
    /// The rebuild's invariants against the live tree (WideBvh::check()).
    void check(const WideBvh& live) const;

private:
    void start(const WideBvh& live);
    /// Empties what one rebuild cycle accumulates: the log, the skipped gathers, the cursors and the
    /// cycle's age, commits and work.
    void begin_cycle();
    /// Advances the rebuild by about `budget` units; swaps the trees when the replay is done.
    void advance(WideBvh& live, std::uint64_t budget);
    std::uint64_t gather_step(const WideBvh& live, std::uint64_t budget);
    /// Makes the next tree hold `uid` as the live tree does now (present or not, same box).
    void replay(const WideBvh& live, Uid uid);
    void swap_trees(WideBvh& live);

    Phase phase_ = Phase::idle;
    std::unique_ptr<WideBvh> next_;        // the tree being built (then the replaced one, disposed)
    std::uint32_t gather_cursor_ = 0;      // the next block to gather
    std::vector<Uid> log_;                 // uids changed since the gathering began
    std::unordered_set<Uid> gather_skip_;  // uids changed while gathering: not gathered
    std::size_t replay_cursor_ = 0;
    std::size_t log_mark_ = 0;             // the log's size at the end of the last commit
    double cycle_age_ = 0;                 // weighted changes since the rebuild in progress gathered
    std::uint32_t cycle_commits_ = 0;      // commits with changes since then
    std::uint64_t cycle_work_ = 0;         // units of the rebuild in progress so far
    std::uint64_t last_cycle_work_ = 0;    // units of the last progressive rebuild, to its swap
    double units_per_object_ = 0;          // units of the last rebuild per object
    std::uint64_t budget_ = 0, work_ = 0;  // of the last commit
};

}  // namespace rcb
