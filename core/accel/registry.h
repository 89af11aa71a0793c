#pragma once
/// Structures by name (pbrt-style: one factory by name, unknown names and parameters reported).
/// A new structure of rcbench adds one line to registry.cpp and nothing else; a program linking
/// rcbench as a library adds its own with register_structure (below), without editing rcbench.

#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/accel/params.h"
#include "core/accel/structure.h"

namespace rcb {

struct StructureInfo {
    std::string name;
    std::string summary;
    std::vector<ParamSpec> params;
    /// Makes the structure from a parameter object (defaults for missing keys); `path` prefixes
    /// error messages, e.g. "structures[2].params" or "--param".
    std::function<std::unique_ptr<Structure>(const nlohmann::json& params, const std::string& path)> make;

    /// Every parameter at its default.
    nlohmann::json defaults() const;
    /// `params` completed with the defaults (what a result records), after validation; parameters
    /// not recorded at their default (ParamSpec::recorded_when_default) are left out then.
    nlohmann::json complete(const nlohmann::json& params, const std::string& path) const;
};

/// Every registered structure, in registration order: rcbench's own, then those added by
/// register_structure. A deque, so that references (find_structure's) stay valid when one is added.
const std::deque<StructureInfo>& structure_registry();
/// Throws InputError "unknown structure 'x' (known: bf, ug, …)".
const StructureInfo& find_structure(std::string_view name);

/// `info` with the parameters the registry gives every structure (`query`, `leaf_bv`:
/// query_level.h): their
/// specs appended, and `make` taking them off the parameters before the structure's own factory
/// sees them. Entries that have them already are returned as they are.
StructureInfo with_common_params(StructureInfo info);

/// The registry entry of a structure type S with a nested `Params` and a constructor from it.
template <class S>
StructureInfo describe_structure(std::string name, std::string summary) {
    StructureInfo info;
    info.name = name;
    info.summary = std::move(summary);
    info.params = param_specs<typename S::Params>();
    info.make = [name](const nlohmann::json& params, const std::string& path) -> std::unique_ptr<Structure> {
        return std::make_unique<S>(params_from_json<typename S::Params>(params, path, name));
    };
    return with_common_params(std::move(info));
}

/// Adds a structure to the registry, after rcbench's own, so that find_structure, simulate, the
/// differential tests (test::expect_matches_ground_truth) and everything that lists the registry
/// know it by name. Returns the registered entry. Refused with an InputError naming the structure:
/// a name that is not 1 to 64 ASCII letters, digits, '_' or '-' (names go into CSV, SQLite and
/// command lines), "all" (the CLI's word for every structure), a name already registered, an
/// empty `make`, or a parameter default outside its own range. Register at start-up, before any
/// thread uses the registry: it is not locked.
///
///     struct SweepList : rcb::StructureBase<SweepList> { struct Params {…}; explicit SweepList(const Params&); … };
///     rcb::register_structure<SweepList>("sweep", "objects sorted by min x, swept per ray");
///     rcb::simulate(recording, rcb::find_structure("sweep"), {});
const StructureInfo& register_structure(StructureInfo info);

/// register_structure(describe_structure<S>(name, summary)).
template <class S>
const StructureInfo& register_structure(std::string name, std::string summary) {
    return register_structure(describe_structure<S>(std::move(name), std::move(summary)));
}

}  // namespace rcb
