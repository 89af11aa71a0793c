// Every registered structure, the registry iterated (no names here), against the double-precision
// ground truth on the hard scenes at parameter sets drawn from its own ParamSpecs (ranges, integers,
// reals, choices, booleans: test::random_params). test::expect_matches_ground_truth verifies every
// ray at the configuration's own contract, runs the counting pass and validate() after the build
// and after every frame's update. The seed is printed on failure; RCB_CONFORMANCE_SEED=<n> draws
// other sets.
#include <gtest/gtest.h>

#include <cctype>
#include <cstdlib>
#include <set>
#include <string>
#include <vector>

#include "core/accel/registry.h"
#include "core/base/random.h"
#include "tests/test_scenes.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

/// Parameter sets per structure: a few seconds per structure under the sanitizers.
constexpr int kDraws = 4;

std::uint64_t conformance_seed() {
    const char* text = std::getenv("RCB_CONFORMANCE_SEED");
    return text != nullptr && *text != '\0' ? std::stoull(text) : 20231;
}

std::vector<std::string> registered_names() {
    std::vector<std::string> names;
    for (const StructureInfo& info : structure_registry()) names.push_back(info.name);
    return names;
}

const std::vector<test::NamedScene>& scenes() {
    static const std::vector<test::NamedScene> hard = test::hard_scenes();
    return hard;
}

class Conformance : public ::testing::TestWithParam<std::string> {};

TEST_P(Conformance, MatchesTheGroundTruthOnTheHardScenesAtRandomParameters) {
    const StructureInfo& info = find_structure(GetParam());
    const std::uint64_t seed = conformance_seed();
    // One stream per structure, so that adding a structure leaves the others' draws alone.
    std::uint64_t stream = seed;
    for (const char c : info.name) stream = stream * 131 + std::uint8_t(c);
    Random rng(stream);
    for (int draw = 0; draw < kDraws; ++draw) {
        // Guards (the *_guard switches) stay on: off, they lift the bounds on memory and time that
        // keep a hard scene small (hg without its entries guard splits without limit).
        std::set<std::string> guards;
        for (const ParamSpec& p : info.params)
            if (p.name.ends_with("_guard")) guards.insert(p.name);
        const nlohmann::json params = test::random_params(info, rng, guards);
        SCOPED_TRACE("RCB_CONFORMANCE_SEED=" + std::to_string(seed) + ", draw " + std::to_string(draw) + ": " +
                     info.name + ' ' + params.dump());
        for (const test::NamedScene& s : scenes())
            test::expect_matches_ground_truth(s.recording, info.name, params, s.name);
    }
}

/// A test name from a structure name: letters, digits and '_' (registered names may hold '-').
std::string test_name(const ::testing::TestParamInfo<std::string>& info) {
    std::string name = info.param;
    for (char& c : name)
        if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
    return name;
}

INSTANTIATE_TEST_SUITE_P(Registry, Conformance, ::testing::ValuesIn(registered_names()), test_name);

}  // namespace
}  // namespace rcb
