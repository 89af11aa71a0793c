#pragma once
/// Performance-model counters (thesis §5.1, eq. 5.4: C = C_RB·(N_TP + N_FP) + C_T·N_T + C_PREP)
/// and the traversal policies.
///
/// A structure's traversal is a template on a policy. The timed pass runs it with `NoCounting`,
/// whose calls compile to nothing; the counting pass runs the very same code with `Counting`.
/// Nothing is counted while timing, and nothing is locked. `CandidatesOf<P>` is either policy at
/// the candidate level: the traversal skips the final test of an object's box (and counts none)
/// and yields everything it reaches, as an engine's broad phase hands its narrow phase.

#include <cstdint>

#include "accel/model/cache_model.h"
#include "accel/model/outcome_predictor.h"

namespace rcb {

/// Sums over a batch of rays.
struct Counters {
    std::uint64_t n_t = 0;        ///< traversal steps: BVH nodes or grid cells visited
    std::uint64_t n_th = 0;       ///< of a tree's steps, node boxes hit: children pushed (0 for grids)
    std::uint64_t n_rb = 0;       ///< ray–box tests against objects' boxes
    std::uint64_t n_tp = 0;       ///< objects the traversal reported (box tests that hit, or candidates)
    std::uint64_t n_dup = 0;      ///< box tests that hit an object already reported (a grid's other cells)
    std::uint64_t n_ro = 0;       ///< narrow-phase tests of exact shapes (thesis eq. 5.3, C_RO)
    std::uint64_t n_ro_hits = 0;  ///< of those, the shapes hit
    std::uint64_t n_mp = 0;       ///< steps whose outcome a history predictor missed (outcome_predictor.h)
    std::uint64_t n_miss = 0;     ///< lines a simulated private cache fetched for the batch (cache_model.h)

    /// False positives: objects tested but not hit (thesis N_FP = N_RB − N_TP; N_TFP once shapes
    /// exist).
    std::uint64_t n_fp() const { return n_rb - n_tp; }
    /// Bounding-volume false positives (thesis N_BFP): box hit, shape missed.
    std::uint64_t n_bfp() const { return n_ro - n_ro_hits; }

    Counters& operator+=(const Counters& o) {
        n_t += o.n_t, n_th += o.n_th, n_rb += o.n_rb, n_tp += o.n_tp, n_dup += o.n_dup, n_ro += o.n_ro,
            n_ro_hits += o.n_ro_hits, n_mp += o.n_mp, n_miss += o.n_miss;
        return *this;
    }
    friend bool operator==(const Counters&, const Counters&) = default;
};

struct NoCounting {
    static constexpr bool enabled = false;
    static constexpr bool candidates = false;
    constexpr void traversal(std::uint64_t = 1) {}
    constexpr void node_hits(std::uint64_t = 1) {}
    constexpr void box_tests(std::uint64_t = 1) {}
    constexpr void hits(std::uint64_t = 1) {}
    constexpr void duplicates(std::uint64_t = 1) {}
    constexpr void reads(const void*, std::size_t) {}
    constexpr void branch(std::uint32_t) {}
};

struct Counting {
    static constexpr bool enabled = true;
    static constexpr bool candidates = false;
    Counters* sums;
    /// Where set, each step's outcome (what the counters did since the step before) goes to it.
    OutcomePredictor* predictor = nullptr;
    /// Where set, the cells, blocks and nodes the traversal reads go to it (cache_model.h).
    CacheModel* cache = nullptr;

    void traversal(std::uint64_t n = 1) {
        if (predictor) predictor->next_step(sums->n_th, sums->n_rb, sums->n_tp);
        sums->n_t += n;
    }
    void node_hits(std::uint64_t n = 1) { sums->n_th += n; }
    void box_tests(std::uint64_t n = 1) { sums->n_rb += n; }
    void hits(std::uint64_t n = 1) { sums->n_tp += n; }
    /// A box hit whose object this ray already reported: dropped, but its lane, slot and stamp read.
    void duplicates(std::uint64_t n = 1) { sums->n_dup += n; }
    void reads(const void* p, std::size_t bytes) {
        if (cache) cache->read(p, bytes);
    }
    /// A branch the step takes beyond what the counters show (OutcomePredictor::branch).
    void branch(std::uint32_t bits) {
        if (predictor) predictor->branch(bits);
    }
};

/// `Policy` at the candidate level (see the top of this file).
template <class Policy>
struct CandidatesOf : Policy {
    static constexpr bool candidates = true;
    constexpr void box_tests(std::uint64_t = 1) {}
};

}  // namespace rcb
