#include "accel/interface/cast_arena.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>

namespace rcb {

struct CastArena::Impl {
    explicit Impl(int threads) : arena(threads) {}
    tbb::task_arena arena;
};

CastArena::CastArena(int threads) : impl_(std::make_unique<Impl>(threads)), threads_(threads) {}

CastArena::~CastArena() = default;

void CastArena::run_erased(std::size_t chunks, void (*call)(void*, std::size_t, int), void* body) {
    // One task per thread, each taking chunks from the counter until none is left. A task that no
    // worker picks up in time is run by the caller after its own, and finds nothing left to take:
    // the caller never waits for a thread that has not started.
    alignas(64) std::atomic<std::size_t> next{0};
    const std::size_t takers = std::min(chunks, std::size_t(threads_));
    impl_->arena.execute([&] {
        tbb::parallel_for(
            tbb::blocked_range<std::size_t>(0, takers, 1),
            [&](const tbb::blocked_range<std::size_t>&) {
                const int slot = tbb::this_task_arena::current_thread_index();
                for (std::size_t c = next.fetch_add(1, std::memory_order_relaxed); c < chunks;
                     c = next.fetch_add(1, std::memory_order_relaxed))
                    call(body, c, slot);
            },
            tbb::simple_partitioner());
    });
}

void RayChunks::plan(std::size_t rays, int threads) {
    const std::size_t share = kShare * std::size_t(std::max(threads, 1));
    bounds_.assign(1, 0);
    for (std::size_t left = rays; left > 0;) {
        const std::size_t n = std::min(left, std::max(kMinRays, (left + share - 1) / share));
        bounds_.push_back(bounds_.back() + n);
        left -= n;
    }
    taken_.assign(chunks(), Taken{});
    if (slots_.size() < std::size_t(std::max(threads, 1))) slots_.resize(std::size_t(std::max(threads, 1)));
    for (SlotLists& s : slots_) s.lists.clear();
}

std::size_t RayChunks::chunk_of(std::size_t ray) const {
    return std::size_t(std::upper_bound(bounds_.begin(), bounds_.end(), ray) - bounds_.begin()) - 1;
}

HitLists& RayChunks::start(std::size_t c, int slot) {
    HitLists& lists = slots_[std::size_t(slot)].lists;
    taken_[c] = {slot, static_cast<std::uint32_t>(lists.rays())};
    return lists;
}

void RayChunks::join(HitLists& out) const {
    out.clear();
    std::size_t hits = 0;
    for (const SlotLists& s : slots_) hits += s.lists.uids.size();
    out.uids.reserve(hits);
    out.offsets.reserve(bounds_.back() + 1);
    for (std::size_t c = 0; c < chunks(); ++c) {
        const HitLists& part = slots_[std::size_t(taken_[c].slot)].lists;
        const std::size_t first = taken_[c].first, last = first + size(c);
        const std::uint32_t from = part.offsets[first];
        const auto base = static_cast<std::uint32_t>(out.uids.size());
        out.uids.insert(out.uids.end(), part.uids.begin() + from, part.uids.begin() + part.offsets[last]);
        for (std::size_t r = first + 1; r <= last; ++r) out.offsets.push_back(base + (part.offsets[r] - from));
    }
}

std::vector<std::size_t> RayChunks::rays_per_slot() const {
    std::vector<std::size_t> rays(slots_.size(), 0);
    for (std::size_t c = 0; c < chunks(); ++c)
        if (taken_[c].slot >= 0) rays[std::size_t(taken_[c].slot)] += size(c);
    return rays;
}

std::size_t RayChunks::memory_bytes() const {
    std::size_t bytes = bounds_.capacity() * sizeof(std::size_t) + taken_.capacity() * sizeof(Taken) +
                        slots_.capacity() * sizeof(SlotLists);
    for (const SlotLists& s : slots_)
        bytes += s.lists.uids.capacity() * sizeof(Uid) + s.lists.offsets.capacity() * sizeof(std::uint32_t);
    return bytes;
}

}  // namespace rcb
