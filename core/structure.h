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
/// timed pass (`NoCounting`) and the counting pass (`Counting`), see counters.h.

#include <cstddef>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

#include "core/counters.h"
#include "core/geometry.h"
#include "core/hit_lists.h"
#include "core/params.h"
#include "core/scene.h"

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

    /// All hits of every ray (the timed batch). Queries may use the structure's scratch state, so
    /// they are not const; one batch at a time.
    virtual void cast(std::span<const Segment> rays, HitLists& out) = 0;
    /// The same traversal with the counters on (the counting pass); adds to `counters`.
    virtual void cast_counted(std::span<const Segment> rays, HitLists& out, Counters& counters) = 0;
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
    virtual void validate() const = 0;
};

/// validate()'s one way to fail: std::logic_error "<structure>: <what is broken>" (a bug in the
/// structure, never bad input).
[[noreturn]] inline void broken_invariant(std::string_view structure, const std::string& what) {
    throw std::logic_error(std::string(structure) + ": " + what);
}

/// Implements the queries of `Structure` from `Derived::traverse` (see the top of this file).
template <class Derived>
class StructureBase : public Structure {
public:
    void cast(std::span<const Segment> rays, HitLists& out) override {
        NoCounting count;
        at_level(count, [&](auto& policy) { cast_all(rays, out, policy); });
    }
    void cast_counted(std::span<const Segment> rays, HitLists& out, Counters& counters) override {
        Counting count{&counters};
        at_level(count, [&](auto& policy) { cast_all(rays, out, policy); });
    }
    std::optional<Hit> cast_closest(const Segment& segment) override {
        NoCounting count;
        std::optional<Hit> best;
        at_level(count, [&](auto& policy) {
            derived().traverse(segment, policy, [&](Uid uid, float t) {
                if (!best || t < best->t || (t == best->t && uid < best->uid)) best = Hit{uid, t};
                return true;
            });
        });
        return best;
    }
    bool cast_any(const Segment& segment) override {
        NoCounting count;
        bool any = false;
        at_level(count, [&](auto& policy) {
            derived().traverse(segment, policy, [&](Uid, float) {
                any = true;
                return false;
            });
        });
        return any;
    }
    void set_candidates_only(bool on) override { candidates_ = on; }

private:
    Derived& derived() { return static_cast<Derived&>(*this); }

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

    bool candidates_ = false;

    template <class Count>
    void cast_all(std::span<const Segment> rays, HitLists& out, Count& count) {
        out.clear();
        out.offsets.reserve(rays.size() + 1);
        for (const Segment& s : rays) {
            derived().traverse(s, count, [&](Uid uid, float) {
                out.uids.push_back(uid);
                return true;
            });
            out.end_ray();
        }
    }
};

}  // namespace rcb
