#pragma once
/// Per-thread query state shared by several structures (structure.h: StructureBase keeps one per
/// thread of a ray batch, so traversals themselves are const).

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace rcb {

/// Cache line size: the scratch of two threads never shares a line, so that pushes and pops on one
/// thread do not invalidate the other's cache (false sharing).
inline constexpr std::size_t kCacheLine = 64;

/// A traversal stack (the BVHs): sized by the structure's fit() from its height, never per ray.
/// The entries start a cache line into the buffer and end a line before its end, so the hot bottom
/// of the stack shares no line with another allocation.
struct alignas(kCacheLine) StackScratch {
    static constexpr std::size_t kPad = kCacheLine / sizeof(std::uint32_t);
    std::vector<std::uint32_t> buffer;
    void fit(std::size_t need) {
        if (buffer.size() < need + 2 * kPad) buffer.resize(need + 2 * kPad);
    }
    std::uint32_t* stack() { return buffer.data() + kPad; }
    std::size_t memory_bytes() const { return buffer.capacity() * sizeof(std::uint32_t); }
};

/// Mailboxes of the grids: per object slot the id of the last query that reported it, so that an
/// object stored in several cells is reported once per ray. Ids only grow, so a slot freed and
/// reused keeps an old id that no later query has; on the wrap every id is forgotten.
struct alignas(kCacheLine) StampScratch {
    std::uint32_t stamp = 0;
    std::vector<std::uint32_t> stamps;  // slot → id of the last query that reported it
    std::vector<std::uint8_t> tested;   // the uniform grid's thesis_reset mode: slot → reported
    /// Room for `slots` slots (new ones never reported).
    void fit(std::size_t slots, bool reset_flags) {
        if (stamps.size() < slots) stamps.resize(slots, 0u);
        if (reset_flags && tested.size() < slots) tested.resize(slots, 0);
    }
    /// A fresh id for the next query.
    std::uint32_t next() {
        if (++stamp == 0) {  // wrapped: forget every old id once per 2^32 queries
            std::fill(stamps.begin(), stamps.end(), 0u);
            stamp = 1;
        }
        return stamp;
    }
    std::size_t memory_bytes() const { return stamps.capacity() * sizeof(std::uint32_t) + tested.capacity(); }
};

}  // namespace rcb
