#pragma once
/// Hit policies of the query kinds (scene.h, QueryKind) as visitors of a structure's one traversal
/// (structure.h): all hits, the closest hit and any hit share the loop, as in Jolt's collectors
/// and madmann91/bvh v2's traversal callbacks.
///
/// A visitor may expose `t_limit`, the segment parameter beyond which nothing can change its
/// answer (the closest hit so far). A traversal reads it with visit_limit() and may skip a node
/// or a cell that the segment enters only after it, and visit near nodes first; a visitor
/// without one (all hits) reads as +infinity, so the all-hits traversal compiles as before. The
/// limit only ever prunes: a traversal that ignores it still gives the right answer.

#include <concepts>
#include <limits>

#include "core/scene/scene.h"

namespace rcb {

/// The nearest hit: smallest entry t, ties to the smallest uid (docs/accuracy.md, "Query kinds").
struct ClosestHit {
    Uid uid = 0;
    float t_limit = std::numeric_limits<float>::infinity();  ///< the best t so far
    bool found = false;

    bool operator()(Uid u, float t) {
        if (!found || t < t_limit || (t == t_limit && u < uid)) {
            uid = u;
            t_limit = t;
            found = true;
        }
        return true;
    }
};

/// Any hit: the first one met ends the traversal.
struct AnyHit {
    Uid uid = 0;
    bool found = false;

    bool operator()(Uid u, float) {
        uid = u;
        found = true;
        return false;
    }
};

template <class Visit>
concept HasTLimit = requires(const Visit& v) {
    { v.t_limit } -> std::convertible_to<float>;
};

/// The visitor's t_limit, or +infinity for a visitor without one. Entries at exactly the limit
/// must still be visited: a tie goes to the smaller uid.
template <class Visit>
inline float visit_limit(const Visit& visit) {
    if constexpr (HasTLimit<Visit>)
        return visit.t_limit;
    else
        return std::numeric_limits<float>::infinity();
}

}  // namespace rcb
