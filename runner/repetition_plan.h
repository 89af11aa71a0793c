#pragma once
/// The one planner of repeated measurements: `rcbench run` orders an experiment's cells with it,
/// `tune` and `advise` their configurations (tuner/tuning.h, measure and measure_interleaved).
///
/// Repetition-major: repetition r of every item runs before repetition r + 1 of any, so one item's
/// repetitions are spread over the whole session and their spread measures the machine's drift
/// (the noise floor, Kalibera and Jones, "Rigorous Benchmarking in Reasonable Time", ISMM 2013)
/// instead of biasing the ratio between two items measured minutes apart. Within a repetition the
/// items keep their order, or, given a seed, are shuffled by the seed and the repetition (the same
/// seed gives the same order): what ran just before an item then changes from repetition to
/// repetition (Mytkowicz et al., "Producing Wrong Data Without Doing Anything Obviously Wrong!",
/// ASPLOS 2009, on measurement bias from a fixed setup).

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

namespace rcb {

/// One measurement of a plan: repetition `repetition` of item `item`.
struct PlannedRun {
    std::uint32_t repetition = 0;
    std::size_t item = 0;
    bool operator==(const PlannedRun&) const = default;
};

/// The order of `items` items (0 .. items − 1) in repetition `repetition`: as they are without a
/// seed, else shuffled by Random(mix_seed(seed, repetition)) (core/base/random.h).
std::vector<std::size_t> repetition_order(std::size_t items, std::uint32_t repetition,
                                          std::optional<std::uint64_t> seed);

/// Repetitions 0 .. repetitions − 1 of `items` items, repetition-major, each repetition in
/// repetition_order.
std::vector<PlannedRun> repetition_plan(std::size_t items, std::uint32_t repetitions,
                                        std::optional<std::uint64_t> seed);

}  // namespace rcb
