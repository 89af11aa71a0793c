#include "core/accel/cast_arena.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

namespace rcb {

struct CastArena::Impl {
    explicit Impl(int threads) : arena(threads) {}
    tbb::task_arena arena;
};

CastArena::CastArena(int threads) : impl_(std::make_unique<Impl>(threads)), threads_(threads) {}

CastArena::~CastArena() = default;

void CastArena::run_erased(std::size_t chunks, void (*call)(void*, std::size_t, int), void* body) {
    impl_->arena.execute([&] {
        // One chunk per task (grain 1, no further splitting): the caller sized the chunks.
        tbb::parallel_for(
            tbb::blocked_range<std::size_t>(0, chunks, 1),
            [&](const tbb::blocked_range<std::size_t>& r) {
                const int slot = tbb::this_task_arena::current_thread_index();
                for (std::size_t c = r.begin(); c != r.end(); ++c) call(body, c, slot);
            },
            tbb::simple_partitioner());
    });
}

}  // namespace rcb
