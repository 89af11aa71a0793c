#include "sim/cache_sweep.h"

namespace rcb {

namespace {
constexpr std::size_t kWordsPerLine = 64 / sizeof(std::uint64_t);
}

CacheSweep::CacheSweep(std::uint64_t bytes) : buffer_(bytes / 64 * kWordsPerLine) {
    // Written once, so every page is backed before the first sweep and no sweep takes a page fault.
    for (std::size_t i = 0; i < buffer_.size(); ++i) buffer_[i] = i;
}

void CacheSweep::sweep() const {
    std::uint64_t sum = 0;
    for (std::size_t i = 0; i < buffer_.size(); i += kWordsPerLine) sum += buffer_[i];
    // A volatile store of the sum: the reads have an effect the compiler must keep.
    volatile std::uint64_t sink = sum;
    (void)sink;
}

}  // namespace rcb
