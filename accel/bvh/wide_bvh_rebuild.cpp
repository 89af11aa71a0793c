#include "accel/bvh/wide_bvh_rebuild.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "accel/bvh/wide_bvh.h"

namespace rcb {

namespace {
constexpr int kLanes = WideBvh::kLanes;
}  // namespace

// PhysX's dynamic pruner keeps one tree for queries while the next one is built over many frames,
// new objects in a side structure meanwhile; Jolt's quad tree builds the next tree while the old
// one answers, then swaps. Here the live tree takes every change as before (so no side structure
// is needed), and the next tree is built from a gathering of the live objects, a budget of work
// per commit; the uids changed since the gathering began are logged and replayed into the next
// tree (present or not, same box as in the live tree), then the trees swap and the replaced one is
// freed, again within the budget. Answers come from the live tree throughout, so they stay exact.

WideBvhRebuild::WideBvhRebuild() = default;
WideBvhRebuild::~WideBvhRebuild() = default;

void WideBvhRebuild::reset() {
    phase_ = Phase::idle;
    next_.reset();
    begin_cycle();
    last_cycle_work_ = budget_ = work_ = 0;
}

void WideBvhRebuild::begin_cycle() {
    log_.clear();
    log_mark_ = 0;
    gather_skip_.clear();
    replay_cursor_ = 0;
    cycle_age_ = 0;
    cycle_commits_ = 0;
    cycle_work_ = 0;
}

void WideBvhRebuild::estimate(std::uint64_t build_work, std::size_t objects) {
    units_per_object_ = double(build_work) / double(std::max<std::size_t>(1, objects)) + 2;
}

void WideBvhRebuild::commit(WideBvh& live, std::uint64_t changes, double weighted) {
    cycle_age_ += weighted;
    ++cycle_commits_;
    const WideBvh::Params& params = live.params_;
    if (phase_ == Phase::idle && live.rebuild_due()) {
        if (params.rebuild_speed <= 0) {
            live.rebuild();
            return;
        }
        start(live);
    }
    if (phase_ == Phase::idle) return;
    budget_ = std::uint64_t(std::ceil(params.rebuild_speed * double(changes) * units_per_object_));
    // While replaying, the uids logged since the last commit are replayed on top of the budget: the
    // log then shrinks by the budget's share at every commit, however slow the rebuild.
    if (phase_ == Phase::replay) budget_ += (log_.size() - log_mark_) * kReplayUnits;
    advance(live, budget_);
    log_mark_ = log_.size();
}

void WideBvhRebuild::start(const WideBvh& live) {
    if (!next_) {
        WideBvh::Params p = live.params_;
        p.rebuild_ratio = p.rebuild_after = p.rebuild_speed = 0;
        p.rebuild_every = 0;
        p.cast_threads = p.threads = 1;  // the next tree is built and replayed into on the calling thread
        next_ = std::make_unique<WideBvh>(p);
    }
    const std::size_t n = live.where_.size();
    next_->builder_.items().clear();
    next_->builder_.items().reserve(n);
    next_->where_.reserve_like(live.where_);
    phase_ = Phase::gather;
    gather_cursor_ = 0;
    begin_cycle();
}

void WideBvhRebuild::advance(WideBvh& live, std::uint64_t budget) {
    // The next tree counts the blocks its build, replay and refit write, and those its replay's
    // descents read; the live tree reports them.
    const std::uint64_t next_writes = next_->writes_, next_work = next_->update_work_;
    while (work_ < budget && phase_ != Phase::idle) {
        std::uint64_t w = 0;
        switch (phase_) {
            case Phase::gather:
                w = gather_step(live, budget - work_);
                break;
            case Phase::build:
                w = next_->builder_.step(*next_, budget - work_);
                if (next_->builder_.done()) {
                    next_->builder_.end(*next_);
                    phase_ = Phase::replay;
                }
                break;
            case Phase::replay:
                while (work_ + w < budget && replay_cursor_ < log_.size()) {
                    replay(live, log_[replay_cursor_++]);
                    w += kReplayUnits;
                }
                next_->apply_moves();  // the next tree holds what was replayed (check())
                if (replay_cursor_ == log_.size()) {
                    work_ += w, cycle_work_ += w, w = 0;
                    swap_trees(live);
                }
                break;
            case Phase::dispose: {
                // The index's map entries one by one (its flat array is one allocation).
                WideBvhIndex& index = next_->where_;
                const std::uint64_t left = (budget - work_ + kDisposeUnits - 1) / kDisposeUnits;
                w += index.drop_some(std::size_t(left)) * kDisposeUnits;
                if (index.map_empty()) {  // the rest is a few arrays, freed at once
                    next_->clear_tree();
                    std::vector<WideBvh::Block>().swap(next_->blocks_);
                    std::vector<std::uint32_t>().swap(next_->dirty_);
                    index.release();
                    phase_ = Phase::idle;
                }
                break;
            }
            case Phase::idle:
                break;
        }
        work_ += w;
        cycle_work_ += w;
    }
    live.writes_ += next_->writes_ - next_writes;
    live.update_work_ += next_->update_work_ - next_work;
}

std::uint64_t WideBvhRebuild::gather_step(const WideBvh& live, std::uint64_t budget) {
    std::uint64_t w = 0;
    std::vector<SahItem>& items = next_->builder_.items();
    const std::vector<WideBvh::Block>& blocks = live.blocks_;
    while (w < budget && gather_cursor_ < blocks.size()) {
        const WideBvh::Block& b = blocks[gather_cursor_++];
        ++w;
        if (!b.leaf) continue;
        for (int k = 0; k < b.count; ++k) {
            // An object changed since the gathering began is left to the replay: it may have been
            // gathered already, or not at all (its lane moved).
            const Uid uid = b.ref[k];
            if (gather_skip_.empty() || gather_skip_.count(uid) == 0)
                items.push_back({b.box(k), WideBvhBuilder::centroid(b.box(k)), uid});
        }
        w += b.count;
    }
    if (gather_cursor_ == blocks.size()) {
        gather_skip_.clear();
        next_->builder_.begin(*next_);
        phase_ = Phase::build;
    }
    return w;
}

void WideBvhRebuild::replay(const WideBvh& live, Uid uid) {
    WideBvh& next = *next_;
    constexpr std::uint32_t kAbsent = WideBvhIndex::kAbsent;
    const std::uint32_t in_live = live.where_.find(uid), in_next = next.where_.find(uid);
    if (in_live == kAbsent) {
        if (in_next != kAbsent) next.remove(uid);
        return;
    }
    const Aabb box = live.blocks_[in_live / kLanes].box(int(in_live % kLanes));
    if (in_next == kAbsent)
        next.insert(Object(uid, box));
    else if (!(next.blocks_[in_next / kLanes].box(int(in_next % kLanes)) == box))
        next.move(Object(uid, box));
}

void WideBvhRebuild::swap_trees(WideBvh& live) {
    WideBvh& next = *next_;
    next.commit();  // refits what the replay changed
    std::swap(live.blocks_, next.blocks_);
    std::swap(live.root_, next.root_);
    std::swap(live.free_, next.free_);
    std::swap(live.free_count_, next.free_count_);
    std::swap(live.leaves_, next.leaves_);
    std::swap(live.where_, next.where_);
    std::swap(live.dirty_, next.dirty_);
    std::swap(live.max_depth_, next.max_depth_);
    std::swap(live.sah_sum_, next.sah_sum_);
    std::swap(live.sah_largest_term_, next.sah_largest_term_);
    live.total_after_build_ = live.total_sah();
    live.age_ = cycle_age_;
    live.commits_ = cycle_commits_;
    ++live.counts_.rebuilds;
    last_cycle_work_ = cycle_work_;
    units_per_object_ = double(cycle_work_) / double(std::max<std::size_t>(1, live.where_.size()));
    ++live.rebuilds_;
    log_.clear();
    log_mark_ = 0;
    replay_cursor_ = 0;
    phase_ = Phase::dispose;
}

std::size_t WideBvhRebuild::memory_bytes() const {
    std::size_t bytes = log_.capacity() * sizeof(Uid) + gather_skip_.bucket_count() * sizeof(void*) +
                        gather_skip_.size() * 2 * sizeof(void*);
    if (next_) bytes += next_->memory_bytes();
    return bytes;
}

void WideBvhRebuild::add_stats(nlohmann::json& stats) const {
    static constexpr const char* kPhases[] = {"idle", "gather", "build", "replay", "dispose"};
    stats["rebuild_phase"] = kPhases[int(phase_)];
    stats["rebuild_budget"] = budget_;
    stats["rebuild_work"] = work_;
    stats["rebuilt_objects"] = units_per_object_ > 0 ? double(work_) / units_per_object_ : 0.0;
    stats["last_rebuild_work"] = last_cycle_work_;
}

void WideBvhRebuild::check(const WideBvh& live) const {
    auto fail = [](const std::string& what) { broken_invariant("wbvh", what); };
    if (phase_ == Phase::idle) {
        if (!log_.empty() || replay_cursor_ != 0 || !gather_skip_.empty()) fail("a change log without a rebuild");
        if (next_ && (next_->root_ != WideBvh::kNone || !next_->where_.empty() || !next_->blocks_.empty()))
            fail("the replaced tree is not freed");
        return;
    }
    if (!next_) fail("a rebuild without a next tree");
    if (replay_cursor_ > log_.size()) fail("the replay is past the end of the log");
    if (phase_ != Phase::gather && !gather_skip_.empty()) fail("uids left to skip after the gathering");
    if (phase_ == Phase::dispose) return;
    // The swap's precondition, kept from the gathering on: the next tree (its items while they are
    // gathered and built) holds every live uid with its live box, except uids still to replay.
    const std::unordered_set<Uid> to_replay(log_.begin() + std::ptrdiff_t(replay_cursor_), log_.end());
    auto live_box = [&](Uid uid, const Aabb& box) {
        const std::uint32_t at = live.where_.find(uid);
        return at != WideBvhIndex::kAbsent && live.blocks_[at / kLanes].box(int(at % kLanes)) == box;
    };
    if (phase_ == Phase::replay) {
        next_->check_tree(false);
        next_->where_.for_each([&](Uid uid, std::uint32_t at) {
            if (to_replay.count(uid) == 0 && !live_box(uid, next_->blocks_[at / kLanes].box(int(at % kLanes))))
                fail("uid " + std::to_string(uid) + " of the next tree is not live with that box, and not logged");
        });
        live.where_.for_each([&](Uid uid, std::uint32_t) {
            if (to_replay.count(uid) == 0 && !next_->where_.contains(uid))
                fail("live uid " + std::to_string(uid) + " is not in the next tree, and not logged");
        });
        return;
    }
    std::unordered_set<Uid> gathered;
    for (const SahItem& it : next_->builder_.items()) {
        if (!gathered.insert(it.id).second) fail("uid " + std::to_string(it.id) + " gathered twice");
        if (to_replay.count(it.id) == 0 && !live_box(it.id, it.box))
            fail("uid " + std::to_string(it.id) + " gathered with a box it no longer has, and not logged");
    }
    if (phase_ == Phase::build)
        live.where_.for_each([&](Uid uid, std::uint32_t) {
            if (to_replay.count(uid) == 0 && gathered.count(uid) == 0)
                fail("live uid " + std::to_string(uid) + " was not gathered, and not logged");
        });
}

}  // namespace rcb
