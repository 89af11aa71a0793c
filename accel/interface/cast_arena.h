#pragma once
/// The threads of a parallel ray batch (structure.h: StructureBase::cast with `cast_threads` > 1):
/// a TBB task arena of a fixed size, kept for the structure's lifetime so that a batch does not
/// pay for starting threads, and the cut of a batch into chunks of rays that the arena's threads
/// take one at a time. TBB stays out of the headers that every structure includes.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "core/truth/hit_lists.h"

namespace rcb {

class CastArena {
public:
    explicit CastArena(int threads);
    ~CastArena();
    CastArena(const CastArena&) = delete;
    CastArena& operator=(const CastArena&) = delete;

    int threads() const { return threads_; }

    /// Calls body(chunk, slot) once for every chunk in [0, chunks), on the arena's threads (the
    /// caller among them), and returns when all are done. Each thread takes the next chunk from one
    /// shared counter when it has finished its last, so a thread held up by a costly chunk takes
    /// no more while the others take the rest (self-scheduling; no chunk is bound to a thread
    /// beforehand). `slot`, in [0, threads()), is the running thread's index in the arena: two
    /// chunks running at the same time never share one, so per-slot scratch needs no lock.
    template <class Body>
    void run(std::size_t chunks, Body&& body) {
        run_erased(
            chunks, [](void* b, std::size_t chunk, int slot) { (*static_cast<Body*>(b))(chunk, slot); }, &body);
    }

private:
    void run_erased(std::size_t chunks, void (*call)(void*, std::size_t, int), void* body);

    struct Impl;
    std::unique_ptr<Impl> impl_;
    int threads_;
};

/// How a parallel batch of rays is cut into chunks and its answers put back together.
///
/// The cut depends only on the batch's size and the thread count, never on timing: chunk k holds
/// max(kMinRays, ⌈left / (kShare · threads)⌉) of the `left` rays not yet in a chunk, so the first
/// chunks are long (few claims on the shared counter) and the last ones short (a thread that
/// finishes early finds work until the end). This is guided self-scheduling (Polychronopoulos &
/// Kuck 1987, "Guided self-scheduling: a practical scheduling scheme for parallel
/// supercomputers"), with chunks cut in ray order so that neighbouring rays, which often share an
/// origin, stay together.
///
/// Each thread appends the answers of the chunks it casts to its own lists (one per arena slot, a
/// cache line apart), and records where each chunk's answers begin; join() copies them chunk by
/// chunk in ray order. The result is the one-thread result byte for byte, whichever thread cast
/// which chunk.
class RayChunks {
public:
    /// Rays a chunk holds at least (only the last may hold fewer).
    static constexpr std::size_t kMinRays = 4;
    /// Chunks per thread the rays left are shared among when the next chunk is cut.
    static constexpr std::size_t kShare = 8;

    /// Cuts a batch of `rays` rays for `threads` threads (≥ 1) and forgets the last batch.
    void plan(std::size_t rays, int threads);

    std::size_t chunks() const { return bounds_.size() - 1; }
    /// The first ray of chunk `c` and how many it holds.
    std::size_t begin(std::size_t c) const { return bounds_[c]; }
    std::size_t size(std::size_t c) const { return bounds_[c + 1] - bounds_[c]; }
    /// The chunk that holds ray `ray` (< the batch's rays).
    std::size_t chunk_of(std::size_t ray) const;

    /// Called by the thread in arena slot `slot` before it casts chunk `c`: the lists to append the
    /// chunk's answers to, one closed list per ray (HitLists::end_ray).
    HitLists& start(std::size_t c, int slot);
    /// Every chunk's answers, in ray order, into `out` (cleared first).
    void join(HitLists& out) const;

    /// Per arena slot, the rays it cast in the batch since the last plan() (for tests: the
    /// assignment, not the time, shows whether the work was shared).
    std::vector<std::size_t> rays_per_slot() const;
    /// The slot that cast chunk `c`.
    int slot_of(std::size_t c) const { return taken_[c].slot; }

    /// Bytes held (capacity).
    std::size_t memory_bytes() const;

private:
    struct alignas(64) SlotLists {
        HitLists lists;
    };
    struct Taken {
        int slot = -1;
        std::uint32_t first = 0;  // the chunk's first ray in its slot's lists
    };
    std::vector<std::size_t> bounds_{0};  // chunk c holds the rays [bounds_[c], bounds_[c + 1])
    std::vector<SlotLists> slots_;
    std::vector<Taken> taken_;  // per chunk
};

}  // namespace rcb
