#pragma once
/// The structures and parameter sets the differential fuzzer (fuzz_differential.cpp) replays, read
/// off the registry and each structure's ParamSpecs, so that a registered structure is fuzzed with
/// nothing written here: no structure is named. Header-only, so that rcb_tests checks the same list
/// the fuzzer runs (tests/registry_list_test.cpp) without the fuzzer's clang build.

#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "accel/registry.h"

namespace rcb::fuzz {

/// A parameter at the low end of its range: the setting that stresses a structure most (capacity
/// 1, fewest bins, no margin, the coarsest grid, a guard's threshold 0: off).
inline nlohmann::json lowest(const ParamSpec& p) {
    if (p.kind == ParamKind::integer) return nlohmann::json(static_cast<long long>(p.lo));
    return nlohmann::json(p.lo);
}

/// The settings one structure is fuzzed at: its defaults; each other value of each choice and bool
/// parameter alone (dbvh's mode=rebuild, lbvh's outlier_guard=false, query=candidates, …); each
/// integer and real parameter at its lower bound alone (hg's max_capacity=1 at its default depth);
/// all of them at their lower bounds at once; and that with every bool flipped too (the guards off
/// on a degenerate lattice or tree).
inline std::vector<nlohmann::json> differential_settings(const StructureInfo& info) {
    std::vector<nlohmann::json> out{nlohmann::json::object()};
    for (const ParamSpec& p : info.params) {
        if (p.kind == ParamKind::choice) {
            for (const std::string& c : p.choices)
                if (nlohmann::json(c) != p.default_value) out.push_back({{p.name, c}});
        } else if (p.kind == ParamKind::boolean) {
            out.push_back({{p.name, !p.default_value.get<bool>()}});
        } else if (lowest(p) != p.default_value) {
            out.push_back({{p.name, lowest(p)}});
        }
    }
    nlohmann::json low = nlohmann::json::object(), low_flipped = nlohmann::json::object();
    for (const ParamSpec& p : info.params) {
        if (p.kind == ParamKind::integer || p.kind == ParamKind::real) low[p.name] = low_flipped[p.name] = lowest(p);
        if (p.kind == ParamKind::boolean) low_flipped[p.name] = !p.default_value.get<bool>();
    }
    for (const nlohmann::json& j : {low, low_flipped})
        if (!j.empty() && std::find(out.begin(), out.end(), j) == out.end()) out.push_back(j);
    return out;
}

/// Every registered structure, in registry order, with its settings.
inline std::vector<std::pair<const StructureInfo*, std::vector<nlohmann::json>>> differential_plan() {
    std::vector<std::pair<const StructureInfo*, std::vector<nlohmann::json>>> out;
    for (const StructureInfo& info : structure_registry()) out.emplace_back(&info, differential_settings(info));
    return out;
}

}  // namespace rcb::fuzz
