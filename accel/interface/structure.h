#pragma once
/// The interface every acceleration structure implements, and the CRTP base that turns one
/// templated traversal into all of the interface's queries.
///
/// Virtual calls happen at this level only (a build, a change, a batch of rays), never per node or
/// per cell. A structure writes
///
///     template <class Count, class Visit>
///     void traverse(const Segment& s, Count& count, Visit&& visit);
///
/// which calls `visit(uid, t_enter)` for every object whose box the closed segment meets (t_enter:
/// the segment parameter in [0, 1] where it enters the box) and stops as soon as `visit` returns
/// false. All hits (the workload), closest hit and any hit all run through that one loop, as do the
/// timed pass (`NoCounting`), the counting pass (`Counting`) and the candidate level
/// (`CandidatesOf`), see counters.h. Structures with per-query state use the Scratch form below.

#include <algorithm>
#include <cstddef>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include <nlohmann/json.hpp>

#include "accel/interface/cast_arena.h"
#include "accel/model/counters.h"
#include "accel/interface/hit_policy.h"
#include "core/base/geometry.h"
#include "core/truth/hit_lists.h"
#include "accel/interface/params.h"
#include "core/scene/scene.h"

namespace rcb {

struct Hit {
    Uid uid = 0;
    float t = 0;  ///< where the segment enters the object's box, in [0, 1]
};

class Structure {
public:
    virtual ~Structure() = default;

    /// Replaces the contents by `objects` (unique uids, valid boxes). The build phase.
    virtual void build(std::span<const Object> objects) = 0;
    /// Changes: insert a new uid, remove or move a live one. Callers guarantee the preconditions
    /// (the recording reader validates user input).
    virtual void insert(const Object& object) = 0;
    virtual void remove(Uid uid) = 0;
    virtual void move(const Object& object) = 0;
    /// End of a frame's changes; structures that defer work (rebuild, refit) do it here. The update
    /// phase times the changes and the commit together.
    virtual void commit() {}
    /// The update's footprint: cells, cell entries and tree nodes written by builds, changes and
    /// commits since construction, one count beside each write (a cheap add, so the timed update
    /// carries it). The simulator records its growth over each frame's update (FrameResult::writes).
    /// 0 where a structure keeps none (brute force, the peers).
    virtual std::uint64_t writes() const { return 0; }
    /// The update's work that its writes do not show, in the structure's own unit, summed since
    /// construction; the simulator records its growth over each frame's update
    /// (FrameResult::update_work) and the cost model prices it (c_work, docs/model.md). A unit is
    ///  - linear BVH: a key placed by the full radix sort (n per rebuild that sorts; a rebuild that
    ///    merges from the last order counts only the keys it sorted apart, those out of order);
    ///  - wide BVH: a block read by the descent that chose an inserted or reinserted object's leaf
    ///    (the leaf's depth + 1 per such object; a progressive rebuild's replay into its next tree
    ///    included), and a rebuild's work (gathering, building, replaying, freeing) at 16 of its
    ///    units per block, their ratio in time (wide_bvh.cpp);
    ///  - 0 where a structure counts none (its writes or changes say what its update does).
    virtual std::uint64_t update_work() const { return 0; }

    /// The timed batch: ray i asks `kinds[i]` (every ray all hits when `kinds` is empty) and its
    /// list holds all its hits, or for closest and any at most one uid (the nearest: smallest t,
    /// then smallest uid; any one met). Queries may use the structure's scratch state, so they are
    /// not const; one batch at a time (which may itself run on several threads: see
    /// StructureBase).
    virtual void cast(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out) = 0;
    /// The same traversal with the counters on (the counting pass); adds to `counters`.
    virtual void cast_counted(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out,
                              Counters& counters) = 0;
    /// All hits of every ray (the thesis' workload).
    void cast(std::span<const Segment> rays, HitLists& out) { cast(rays, {}, out); }
    void cast_counted(std::span<const Segment> rays, HitLists& out, Counters& counters) {
        cast_counted(rays, {}, out, counters);
    }
    /// The hit nearest the segment's start (smallest t, then smallest uid), if any.
    virtual std::optional<Hit> cast_closest(const Segment& segment) = 0;
    /// Whether the segment hits anything; stops at the first hit.
    virtual bool cast_any(const Segment& segment) = 0;
    /// The candidate level (counters.h: CandidatesOf) for every query from now on, or back to the
    /// box level. The registry's `query` parameter sets it (query_level.h).
    virtual void set_candidates_only(bool on) = 0;

    virtual std::size_t size() const = 0;
    /// Bytes held by the structure (capacity, not only size: what the process pays).
    virtual std::size_t memory_bytes() const = 0;
    /// Structure-specific measures (e.g. "sah_cost", "depth", "cells"), recorded per frame.
    virtual nlohmann::json stats() const { return nlohmann::json::object(); }
    /// Checks the invariants (every object stored where it must be, bounds enclose children, …);
    /// the first violation goes to broken_invariant (below). Tests call it after every update.
    /// Every structure overrides it; the default serves a structure written before this release,
    /// which overrides validate() instead.
    virtual void check() const { validate(); }
    /// check()'s old name, kept for one release so that a structure written outside rcbench still
    /// builds: override check(). It goes with the next release.
    virtual void validate() const {}
};

/// check()'s one way to fail: std::logic_error "<structure>: <what is broken>" (a bug in the
/// structure, never bad input).
[[noreturn]] inline void broken_invariant(std::string_view structure, const std::string& what) {
    throw std::logic_error(std::string(structure) + ": " + what);
}

/// The `cast_threads` parameter of a structure with a Scratch (below): threads of the timed ray
/// batch. Not recorded at its default (1), so single-thread configurations keep their identity.
template <class P>
constexpr auto cast_threads_field() {
    return Field{"cast_threads",
                 &P::cast_threads,
                 1,
                 64,
                 "threads of the timed ray batch, every query kind (TBB task arena, chunks of rays taken one at "
                 "a time; the hits and counters are the same for every count)",
                 kNotTunedDefaultUnrecorded};
}

/// The scratch of a structure whose traversal keeps none between calls of its own (the peers):
/// `traverse(segment, count, visit)` is called as is, and batches run on one thread.
struct NoScratch {
    std::size_t memory_bytes() const { return 0; }
};

/// Implements the queries of `Structure` from `Derived::traverse` (see the top of this file).
///
/// A structure with per-query mutable state (BVH stacks, grid mailbox stamps, hit flags) keeps it
/// in a `Scratch` and provides
///
///     void prepare();                   // deferred work (rebuild, refit) before queries
///     void fit(Scratch&) const;         // sizes a scratch for the current contents
///     template <class Count, class Visit>
///     void traverse(const Segment&, Count&, Visit&&, Scratch&) const;
///
/// Then `set_cast_threads(n)` with n > 1 lets the timed batch (`cast`), whatever its rays' query
/// kinds (all, closest, any), run in chunks of rays on a task arena of n threads, one scratch per
/// arena slot; the threads take the chunks one at a time, and the answers are joined in ray order,
/// so the result is the single-thread one (cast_arena.h: RayChunks). The counting pass and the
/// single-ray queries (cast_closest, cast_any) stay on the calling thread (scratch 0).
template <class Derived, class Scratch = NoScratch>
class StructureBase : public Structure {
public:
    StructureBase() = default;
    /// A copy has the same thread count and fresh scratch (check() copies some structures).
    StructureBase(const StructureBase& o)
        : candidates_(o.candidates_),
          scratch_(o.scratch_.size()),
          arena_(o.arena_ ? std::make_unique<CastArena>(o.arena_->threads()) : nullptr) {}
    StructureBase& operator=(const StructureBase&) = delete;

    using Structure::cast;
    using Structure::cast_counted;
    void cast(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out) override {
        NoCounting count;
        at_level(count, [&](auto& policy) {
            if constexpr (kScratch) {
                if (arena_ && rays.size() >= kParallelRays) return cast_parallel(rays, kinds, out, policy);
            }
            last_chunks_ = 1;
            last_rays_ = rays.size();
            cast_all(rays, kinds, out, policy);
        });
    }
    void cast_counted(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out,
                      Counters& counters) override {
        OutcomePredictor predictor;
        CacheModel cache;  // cold: what the batch fetches (cache_model.h)
        Counting count{&counters, &predictor, &cache};
        at_level(count, [&](auto& policy) { cast_all(rays, kinds, out, policy); });
        predictor.end(counters.n_th, counters.n_rb, counters.n_tp);
        counters.n_mp += predictor.mispredicted();
        counters.n_miss += cache.misses();
    }
    std::optional<Hit> cast_closest(const Segment& segment) override {
        NoCounting count;
        ClosestHit closest;
        at_level(count, [&](auto& policy) {
            ready();
            run(segment, policy, scratch_[0], closest);
        });
        if (!closest.found) return std::nullopt;
        return Hit{closest.uid, closest.t_limit};
    }
    bool cast_any(const Segment& segment) override {
        NoCounting count;
        AnyHit any;
        at_level(count, [&](auto& policy) {
            ready();
            run(segment, policy, scratch_[0], any);
        });
        return any.found;
    }
    void set_candidates_only(bool on) override { candidates_ = on; }

    /// Threads of the timed batch (1: the calling thread only).
    int cast_threads() const { return arena_ ? arena_->threads() : 1; }
    /// Chunks the last timed batch ran in (1: on the calling thread; for tests).
    std::size_t last_cast_chunks() const { return last_chunks_; }
    /// Per arena slot, the rays it cast in the last timed batch (for tests: how the work was shared).
    std::vector<std::size_t> last_cast_rays_per_slot() const {
        return last_chunks_ > 1 ? chunks_.rays_per_slot() : std::vector<std::size_t>{last_rays_};
    }

    /// A batch of fewer rays runs on the calling thread: entering the arena would cost more.
    static constexpr std::size_t kParallelRays = 32;

protected:
    /// Called by a structure's constructor with its `cast_threads` parameter.
    void set_cast_threads(int threads) {
        static_assert(kScratch, "a parallel batch needs the traversal's scratch (see above)");
        arena_ = threads > 1 ? std::make_unique<CastArena>(threads) : nullptr;
        scratch_.resize(std::size_t(std::max(threads, 1)));
    }
    /// Bytes held by the scratches (capacity), for memory_bytes().
    std::size_t scratch_bytes() const {
        std::size_t bytes = scratch_.capacity() * sizeof(Scratch) + (arena_ ? chunks_.memory_bytes() : 0);
        for (const Scratch& s : scratch_) bytes += s.memory_bytes();
        return bytes;
    }

private:
    static constexpr bool kScratch = !std::is_same_v<Scratch, NoScratch>;

    Derived& derived() { return static_cast<Derived&>(*this); }

    /// Deferred work done and scratch 0 sized: the calling thread may query.
    void ready() {
        if constexpr (kScratch) {
            derived().prepare();
            static_cast<const Derived&>(*this).fit(scratch_[0]);
        }
    }
    template <class Count, class Visit>
    void run(const Segment& s, Count& count, Scratch& scratch, Visit&& visit) {
        if constexpr (kScratch)
            static_cast<const Derived&>(*this).traverse(s, count, visit, scratch);
        else
            derived().traverse(s, count, visit);
    }

    /// Runs `body` with `policy`, or with CandidatesOf it at the candidate level.
    template <class Policy, class Body>
    void at_level(Policy& policy, Body&& body) {
        if (candidates_) {
            CandidatesOf<Policy> candidates{policy};
            body(candidates);
        } else {
            body(policy);
        }
    }

    /// The rays' answers into `out`; `kinds` empty: all hits for every ray (the loop the thesis'
    /// workload times, without a branch per ray).
    template <class Count>
    void cast_range(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out, Count& count,
                    Scratch& scratch) {
        auto all = [&](Uid uid, float) {
            out.uids.push_back(uid);
            return true;
        };
        if (kinds.empty()) {
            for (const Segment& s : rays) {
                run(s, count, scratch, all);
                out.end_ray();
            }
            return;
        }
        for (std::size_t i = 0; i < rays.size(); ++i) {
            if (kinds[i] == QueryKind::closest) {
                ClosestHit closest;
                run(rays[i], count, scratch, closest);
                if (closest.found) out.uids.push_back(closest.uid);
            } else if (kinds[i] == QueryKind::any) {
                AnyHit any;
                run(rays[i], count, scratch, any);
                if (any.found) out.uids.push_back(any.uid);
            } else {
                run(rays[i], count, scratch, all);
            }
            out.end_ray();
        }
    }

    template <class Count>
    void cast_all(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out, Count& count) {
        ready();
        out.clear();
        out.offsets.reserve(rays.size() + 1);
        cast_range(rays, kinds, out, count, scratch_[0]);
    }

    /// The batch in chunks on the arena (see above and RayChunks in cast_arena.h). Only the timed
    /// pass comes here: a policy that counts would be shared by the chunks.
    template <class Count>
    void cast_parallel(std::span<const Segment> rays, std::span<const QueryKind> kinds, HitLists& out, Count& count) {
        static_assert(!Count::enabled, "the counting pass runs on one thread");
        derived().prepare();
        chunks_.plan(rays.size(), arena_->threads());
        last_chunks_ = chunks_.chunks();
        arena_->run(chunks_.chunks(), [&](std::size_t c, int slot) {
            Scratch& scratch = scratch_[std::size_t(slot)];
            static_cast<const Derived&>(*this).fit(scratch);
            Count local = count;
            const std::size_t begin = chunks_.begin(c), n = chunks_.size(c);
            cast_range(rays.subspan(begin, n), kinds.empty() ? kinds : kinds.subspan(begin, n), chunks_.start(c, slot),
                       local, scratch);
        });
        chunks_.join(out);
    }

    bool candidates_ = false;
    std::vector<Scratch> scratch_ = std::vector<Scratch>(1);  // one per arena slot; 0: the caller's
    std::unique_ptr<CastArena> arena_;                        // null: one thread
    RayChunks chunks_;                                        // the last parallel batch's cut and answers
    std::size_t last_chunks_ = 0, last_rays_ = 0;
};

}  // namespace rcb
