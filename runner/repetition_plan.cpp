#include "runner/repetition_plan.h"

#include <numeric>

#include "core/base/random.h"

namespace rcb {

std::vector<std::size_t> repetition_order(std::size_t items, std::uint32_t repetition,
                                          std::optional<std::uint64_t> seed) {
    std::vector<std::size_t> order(items);
    std::iota(order.begin(), order.end(), std::size_t(0));
    if (seed) {
        Random rng(mix_seed(*seed, repetition));
        rng.shuffle(order);
    }
    return order;
}

std::vector<PlannedRun> repetition_plan(std::size_t items, std::uint32_t repetitions,
                                        std::optional<std::uint64_t> seed) {
    std::vector<PlannedRun> plan;
    plan.reserve(items * repetitions);
    for (std::uint32_t r = 0; r < repetitions; ++r)
        for (std::size_t i : repetition_order(items, r, seed)) plan.push_back({r, i});
    return plan;
}

}  // namespace rcb
