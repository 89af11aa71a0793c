#pragma once
/// The threads of a parallel ray batch (structure.h: StructureBase::cast with `cast_threads` > 1):
/// a TBB task arena of a fixed size, kept for the structure's lifetime so that a batch does not
/// pay for starting threads. TBB stays out of the headers that every structure includes.

#include <cstddef>
#include <memory>

namespace rcb {

class CastArena {
public:
    explicit CastArena(int threads);
    ~CastArena();
    CastArena(const CastArena&) = delete;
    CastArena& operator=(const CastArena&) = delete;

    int threads() const { return threads_; }

    /// Calls body(chunk, slot) once for every chunk in [0, chunks), on the arena's threads (the
    /// caller among them), and returns when all are done. `slot`, in [0, threads()), is the
    /// running thread's index in the arena: two chunks running at the same time never share one,
    /// so per-slot scratch needs no lock.
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

}  // namespace rcb
