#pragma once
/// A small simulated cache for the counting pass: where a ray's data lies, which the counters of
/// eq. 5.4 do not see.
///
/// N_RB and N_T say how much work a ray does. Rays aimed at one region (the thesis' dense rays,
/// §6.4) reread the same cells and nodes from the core's private cache; rays spread over a scene
/// (centre rays on a map) fetch most of theirs from the shared cache or memory, and cost more per
/// test and step for the same counts. The counting pass hands each cell, block of boxes and node it
/// reads to this model of a private cache of 512 KiB, cold at the start of each batch: fully
/// associative, least recently used, holding whole items (a read of a block keeps the block). N_MISS
/// counts the 64-byte lines of the items it had to fetch: the batch's footprint plus what it
/// evicted and read again. Items, not address lines, so the count does not depend on where the
/// allocator put the structure: the same batch on the same structure counts the same in every
/// process. No prefetcher is modelled. The cost model prices it (C_MISS, docs/model.md).

#include <cstddef>
#include <cstdint>
#include <list>
#include <unordered_map>
#include <utility>

namespace rcb {

class CacheModel {
public:
    static constexpr std::size_t kBytes = std::size_t(512) << 10, kLineBytes = 64;

    /// The traversal reads the item of `bytes` bytes at `p` (a cell, a block, a node).
    void read(const void* p, std::size_t bytes) {
        const auto key = reinterpret_cast<std::uintptr_t>(p);
        if (const auto it = where_.find(key); it != where_.end()) {
            recent_.splice(recent_.begin(), recent_, it->second);  // a hit: now the most recent
            return;
        }
        misses_ += (bytes + kLineBytes - 1) / kLineBytes;
        recent_.emplace_front(key, bytes);
        where_.emplace(key, recent_.begin());
        held_ += bytes;
        while (held_ > kBytes) {  // evict the least recently read
            held_ -= recent_.back().second;
            where_.erase(recent_.back().first);
            recent_.pop_back();
        }
    }
    /// Lines fetched so far.
    std::uint64_t misses() const { return misses_; }

private:
    std::list<std::pair<std::uintptr_t, std::size_t>> recent_;  // (item, bytes), most recent first
    std::unordered_map<std::uintptr_t, std::list<std::pair<std::uintptr_t, std::size_t>>::iterator> where_;
    std::size_t held_ = 0;
    std::uint64_t misses_ = 0;
};

}  // namespace rcb
