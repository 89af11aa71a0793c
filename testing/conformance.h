#pragma once
/// The conformance suite (rcbench::testing): the checks rcbench runs on each of its own structures,
/// for a structure written outside rcbench. One line in a GoogleTest file,
///
///     #include <testing/conformance.h>
///     RCB_CONFORMANCE_TESTS(SweepList, "sweep")
///
/// registers SweepList under "sweep" (unless a structure of that name is registered already) and
/// instantiates five tests, each against the double-precision ground truth (core/truth/):
///   Exactness          every hard scene (generator families and hand-made adversarial cases),
///                      every ray cast as all, closest and any hit, at the defaults;
///   RandomParameters   the same at parameter sets drawn from its ParamSpecs (seeded: RCB_CONFORMANCE_SEED);
///   DifferentialFuzz   a seeded random scene of a few hundred frames (lattice-aligned boxes and rays,
///                      flat, huge and far boxes, zero-length rays) at the fuzzer's settings
///                      (differential_settings.h);
///   BadParameters      every parameter refused outside its spec, naming "params.<name>";
/// and check() after the build and after every frame of every replay. A failure names the
/// scene, the parameters, the frame, the ray and the missing or extra uid.
///
/// rcbench's own structures run the same functions (tests/conformance_test.cpp).

#include <cstdint>
#include <functional>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "accel/registry.h"
#include "core/base/random.h"
#include "core/scene/scene.h"
#include "sim/simulator.h"

namespace rcb::test {

struct NamedScene {
    std::string name;
    Recording recording;
};

/// Small generated presets (uniform, irregular, jittered, clusters) plus hand-made hard cases: an
/// empty scene, one object, identical boxes, identical centroids with different sizes, flat and
/// zero-volume boxes, one huge object around a dense cluster, a crowd of boxes nested around one
/// centre with rays starting inside all of them, axis-parallel rays along box faces, rays starting
/// inside, on and outside the bounds, zero-length rays, inserts far outside the initial bounds,
/// and churn (many inserts, removes, moves). Each has several frames; every ray asks for all hits.
std::vector<NamedScene> hard_scenes();

/// A generated scene of `generator` ("uniform"/"irregular"/...) with `objects`, `frames`, all ray modes.
Recording generated_scene(const std::string& generator, std::uint32_t objects, std::uint32_t frames, std::uint64_t seed,
                          double change_fraction = 0.05);

/// `r` with every ray cast three times, as all, closest and any hit (the three query kinds).
Recording with_every_query_kind(Recording r);

/// A seeded random scene of `frames` frames after the differential fuzzer's (tests/fuzz/
/// fuzz_differential.cpp) distributions: at most 48 objects on a 0.25 lattice (coincident faces),
/// flat, huge and far-away boxes, inserts, removes and moves, axis-parallel and zero-length rays,
/// each ray of a random query kind.
Recording fuzz_scene(std::uint64_t seed, std::uint32_t frames);

/// The message of the InputError `f` throws, "" when it returns. Any other exception goes through.
std::string input_error_of(const std::function<void()>& f);

/// One parameter object for `info`, drawn from its ParamSpecs: each parameter is left at its default
/// one time in four, else drawn from its spec. Booleans and choices uniformly; integers and reals
/// at an end of their range one time in four, otherwise uniformly, or log-uniformly when the range
/// spans orders of magnitude (log_scale, or hi at least 32 times max(lo, 1); integers from
/// max(lo, 1), reals from hi / 10^4 when lo is 0), so "0: off" ends and small values both come up
/// in ranges as wide as 0..10^6. Combinations the structure refuses (an InputError from
/// `make`, e.g. query=candidates with a leaf volume) are drawn again. The parameters named in
/// `keep_default` stay at their defaults.
nlohmann::json random_params(const StructureInfo& info, Random& rng, const std::set<std::string>& keep_default = {});

/// The discrepancies `res` kept (the first few), one line each: "scene S frame F ray R (closest)
/// from (x, y, z) to (x, y, z): missed uid U" (or extra, duplicate); "" when there are none.
std::string describe_mismatches(const SimulationResult& res, const Recording& r, const std::string& scene_name);

/// The check itself, without GoogleTest: replays `r` through the simulator with verification
/// against the ground truth, the counting pass and check() after every frame. "" when every ray
/// is answered exactly, else one line per discrepancy the simulator kept ("scene S frame F ray R
/// (closest): missed uid U"), after a first line naming the structure and parameters; a failed
/// invariant or any other exception is reported the same way, naming the scene.
std::string ground_truth_failures(const Recording& r, const StructureInfo& info, const nlohmann::json& params,
                                  const std::string& scene_name);

/// The bad parameter values `info` must refuse, each with an InputError naming "params.<name>":
/// numbers below and above their range, a fraction for an integer, a string for a number, a number
/// for a bool, a choice outside the list; an unknown parameter and a non-object. "" when all are
/// refused, else one line per value accepted or refused without naming its path.
std::string refusal_failures(const StructureInfo& info);

/// The seed of the random parameters and the fuzz scene: RCB_CONFORMANCE_SEED, else 20231.
std::uint64_t conformance_seed();

/// Parameter sets RCB_CONFORMANCE_TESTS draws beside the defaults, and the frames of its fuzz scene.
inline constexpr int kConformanceDraws = 3;
inline constexpr std::uint32_t kConformanceFuzzFrames = 300;

/// The tests of RCB_CONFORMANCE_TESTS, one per check; each reports through GoogleTest.
void expect_exact_on_hard_scenes(const StructureInfo& info, const nlohmann::json& params = nlohmann::json::object());
void expect_exact_at_random_params(const StructureInfo& info, std::uint64_t seed, int draws);
void expect_exact_under_fuzz(const StructureInfo& info, std::uint64_t seed, std::uint32_t frames);
void expect_refuses_bad_params(const StructureInfo& info);

/// The registered structure `name`, registering S under it first if no structure has that name.
template <class S>
const StructureInfo& conformance_structure(const std::string& name) {
    if (const StructureInfo* known = registered_structure(name)) return *known;
    return register_structure<S>(name, "registered by the conformance suite");
}

}  // namespace rcb::test

/// The conformance tests of structure type `Type` (an identifier: a test suite is named after it)
/// registered under `name`: see the top of this file. Link rcbench::testing and GTest::gtest_main.
#define RCB_CONFORMANCE_TESTS(Type, name)                                                                            \
    TEST(Conformance_##Type, Exactness) {                                                                            \
        ::rcb::test::expect_exact_on_hard_scenes(::rcb::test::conformance_structure<Type>(name));                    \
    }                                                                                                                \
    TEST(Conformance_##Type, RandomParameters) {                                                                     \
        ::rcb::test::expect_exact_at_random_params(::rcb::test::conformance_structure<Type>(name),                   \
                                                   ::rcb::test::conformance_seed(), ::rcb::test::kConformanceDraws); \
    }                                                                                                                \
    TEST(Conformance_##Type, DifferentialFuzz) {                                                                     \
        ::rcb::test::expect_exact_under_fuzz(::rcb::test::conformance_structure<Type>(name),                         \
                                             ::rcb::test::conformance_seed(), ::rcb::test::kConformanceFuzzFrames);  \
    }                                                                                                                \
    TEST(Conformance_##Type, BadParameters) {                                                                        \
        ::rcb::test::expect_refuses_bad_params(::rcb::test::conformance_structure<Type>(name));                      \
    }
