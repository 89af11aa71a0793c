#pragma once
/// A defined cache state before a timed phase: reading a buffer larger than every cache of the
/// machine leaves none of a structure's lines in any level, so the phase that follows starts cold.
///
/// Without it, how much of a structure's update-side memory (index, cells, nodes) is still cached
/// when the next frame's update starts depends on what else used the shared last-level cache
/// meanwhile: the other core, other tenants of the host. That changes from minute to minute, and
/// small updates move with it (docs/model.md as of commit f3b2207, "A cold cache before each update").
/// Mytkowicz et al. 2009 name such state among the causes of wrong data; where it cannot be
/// randomised over, fixing it is the remedy. Cold is also what an engine's broad phase meets: the
/// rest of its frame runs between two updates.

#include <cstdint>
#include <vector>

namespace rcb {

class CacheSweep {
public:
    /// `bytes` of buffer, rounded down to whole 64-byte lines; 0 sweeps nothing.
    explicit CacheSweep(std::uint64_t bytes = 0);
    /// Reads one word of every line of the buffer (a read leaves no dirty line to write back later).
    void sweep() const;
    std::uint64_t bytes() const { return buffer_.size() * sizeof(std::uint64_t); }

private:
    std::vector<std::uint64_t> buffer_;
};

}  // namespace rcb
