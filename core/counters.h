#pragma once
/// Performance-model counters (thesis §5.1, eq. 5.4: C = C_RB·(N_TP + N_FP) + C_T·N_T + C_PREP).
///
/// A structure's traversal is a template on a counting policy. The timed pass runs it with
/// `NoCounting`, whose calls compile to nothing; the counting pass runs the very same code with
/// `Counting`. Nothing is counted while timing, and nothing is locked.

#include <cstdint>

namespace rcb {

/// Sums over a batch of rays.
struct Counters {
    std::uint64_t n_t = 0;   ///< traversal steps: BVH nodes or grid cells visited
    std::uint64_t n_rb = 0;  ///< ray–box tests against objects' boxes
    std::uint64_t n_tp = 0;  ///< tests that hit (objects reported)

    /// False positives: objects tested but not hit (thesis N_FP = N_RB − N_TP).
    std::uint64_t n_fp() const { return n_rb - n_tp; }

    Counters& operator+=(const Counters& o) {
        n_t += o.n_t, n_rb += o.n_rb, n_tp += o.n_tp;
        return *this;
    }
    friend bool operator==(const Counters&, const Counters&) = default;
};

struct NoCounting {
    static constexpr bool enabled = false;
    constexpr void traversal(std::uint64_t = 1) {}
    constexpr void box_tests(std::uint64_t = 1) {}
    constexpr void hits(std::uint64_t = 1) {}
};

struct Counting {
    static constexpr bool enabled = true;
    Counters* sums;
    void traversal(std::uint64_t n = 1) { sums->n_t += n; }
    void box_tests(std::uint64_t n = 1) { sums->n_rb += n; }
    void hits(std::uint64_t n = 1) { sums->n_tp += n; }
};

}  // namespace rcb
