#pragma once
/// Structures by name (pbrt-style: one factory by name, unknown names and parameters reported).
/// A new structure of rcbench adds one line to registry.cpp (name, origin, family, summary) and
/// nothing else: every list of structures is made from the registry; a program linking
/// rcbench as a library adds its own with register_structure (below), without editing rcbench.

#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "accel/interface/params.h"
#include "accel/interface/structure.h"

namespace rcb {

/// Where a structure comes from; the findings and the report filter the registry by it.
enum class Origin {
    thesis,  ///< one of Guo & Liao's (2023) structures, chapter 4: bf ug hg dbvh lbvh
    own,     ///< rcbench's own beyond the thesis (wbvh), and a program's own registered at run time
    peer,    ///< another library's behind the same interface (embree, bullet_dbvt)
};
/// What a structure is, for lists that compare like with like ("every grid").
enum class Family {
    scan,   ///< tests every object per ray: the baseline, not an acceleration structure
    grid,   ///< cells of a lattice walked per ray
    bvh,    ///< a bounding-volume tree
    peer,   ///< another library's structure, its inside not rcbench's
    other,  ///< none of these (the default of register_structure)
};
const char* origin_name(Origin origin);
const char* family_name(Family family);

struct StructureInfo {
    std::string name;
    std::string summary;
    Origin origin = Origin::own;
    Family family = Family::other;
    /// Rank for the tuner's simplicity rule (simplest_within, tuner/tuning.h), lower is simpler:
    /// among candidates within 3% of the fastest the simplest is recommended, as the thesis
    /// prefers the uniform grid (0), then the hash grid (1); every other structure is 2.
    int simplicity = 2;
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
/// The names of the registered structures `keep` accepts, in registration order: the one way a
/// list of structures is made (findings, the tuner, the fuzzers), so a new structure joins them all.
std::vector<std::string> structure_names(const std::function<bool(const StructureInfo&)>& keep = {});
/// Throws InputError "unknown structure 'x' (known: bf, ug, …)".
const StructureInfo& find_structure(std::string_view name);
/// The registered structure `name`, or nullptr: for names read from a database, which may hold
/// structures a program registered and this one does not know.
const StructureInfo* registered_structure(std::string_view name);

/// `info` with the parameters the registry gives every structure (`query`, `leaf_bv`:
/// query_level.h): their
/// specs appended, and `make` taking them off the parameters before the structure's own factory
/// sees them. Entries that have them already are returned as they are.
StructureInfo with_common_params(StructureInfo info);

/// The registry entry of a structure type S with a nested `Params` and a constructor from it.
template <class S>
StructureInfo describe_structure(std::string name, std::string summary, Origin origin = Origin::own,
                                 Family family = Family::other) {
    StructureInfo info;
    info.name = name;
    info.summary = std::move(summary);
    info.origin = origin;
    info.family = family;
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

/// register_structure(describe_structure<S>(name, summary, origin, family)).
template <class S>
const StructureInfo& register_structure(std::string name, std::string summary, Origin origin = Origin::own,
                                        Family family = Family::other) {
    return register_structure(describe_structure<S>(std::move(name), std::move(summary), origin, family));
}

}  // namespace rcb
