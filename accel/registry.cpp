#include "accel/registry.h"
#include "accel/builtin_structures.h"

#include "accel/peers/bullet_dbvt.h"
#include "accel/narrow/narrow_phase.h"
#include "accel/peers/embree_boxes.h"
#include "accel/peers/ode_spaces.h"
#include "accel/scan/brute_force.h"
#include "accel/bvh/dynamic_bvh.h"
#include "accel/bvh/linear_bvh.h"
#include "accel/grid/hash_grid.h"
#include "accel/grid/uniform_grid.h"
#include "accel/bvh/wide_bvh.h"

namespace rcb {
namespace {

/// `info` at rank `simplicity` of the tuner's simplicity rule (StructureInfo::simplicity).
StructureInfo ranked(StructureInfo info, int simplicity) {
    info.simplicity = simplicity;
    return info;
}

std::deque<StructureInfo>& registry() {
    // One entry per structure: name, summary, origin and family (registry.h); the two grids the
    // tuner's simplicity rule prefers are ranked.
    static std::deque<StructureInfo> all = {
        describe_structure<BruteForce>("bf", "brute force: every object's box tested (the baseline, thesis §4.1)",
                                       Origin::thesis, Family::scan),
        describe_structure<DynamicBvh>("dbvh",
                                       "dynamic BVH: Catto/Box2D SAH insertion with branch and bound, fat boxes, "
                                       "rotations, optional full binned-SAH rebuilds (thesis §4.4)",
                                       Origin::thesis, Family::bvh),
        describe_structure<LinearBvh>("lbvh",
                                      "linear BVH: Karras 2012 Morton codes, radix sort, parallel radix tree, atomic "
                                      "bottom-up bounds, rebuilt every frame (thesis §4.5)",
                                      Origin::thesis, Family::bvh),
        describe_structure<WideBvh>("wbvh",
                                    "wide BVH: 8 child boxes per node in SoA lanes, one AVX2 slab test per node and "
                                    "per leaf of up to 8 objects, binned-SAH build, refit, reinsertion and leaf splits "
                                    "on changes, progressive rebuild spread over commits",
                                    Origin::own, Family::bvh),
        ranked(describe_structure<UniformGrid>(
                   "ug", "uniform grid: cells from eq. 4.1, 3D-DDA with mailboxes, incremental updates (thesis §4.2)",
                   Origin::thesis, Family::grid),
               0),
        ranked(
            describe_structure<HashGrid>(
                "hg", "hierarchical hash grid: Jevans-style recursive grids, only non-empty cells hashed (thesis §4.3)",
                Origin::thesis, Family::grid),
            1),
        describe_structure<EmbreeBoxes>("embree",
                                        "peer: Intel Embree 3 user geometry of boxes, all hits recorded in the "
                                        "intersect callback, rebuilt (Morton or binned SAH) or refitted at commit "
                                        "(dynamic scene, a rebuild-versus-refit policy)",
                                        Origin::peer, Family::peer),
        describe_structure<BulletDbvt>("bullet_dbvt",
                                       "peer: Bullet's btDbvt as btDbvtBroadphase runs it (dynamic and fixed trees, "
                                       "moves inside a leaf's fat volume skipped, optimizeIncremental passes per "
                                       "frame) or raw, rayTestInternal with exact leaf tests",
                                       Origin::peer, Family::peer),
        describe_structure<OdeQuadTree>("ode_quadtree",
                                        "peer: ODE's dQuadTreeSpace of box geoms over the scene's ground plane, the "
                                        "segment a ray geom through dSpaceCollide2 (prunes blocks by the ray's AABB) "
                                        "with exact leaf tests",
                                        Origin::peer, Family::peer),
        describe_structure<OdeHash>("ode_hash",
                                    "peer: ODE's dHashSpace of box geoms, the segment a ray geom through "
                                    "dSpaceCollide2 (which scans every geom's AABB) with exact leaf tests",
                                    Origin::peer, Family::peer),
        describe_structure<OdeSap>("ode_sap",
                                   "peer: ODE's dSweepAndPruneSpace of box geoms, the segment a ray geom through "
                                   "dSpaceCollide2 (which scans every geom's AABB) with exact leaf tests",
                                   Origin::peer, Family::peer),
    };
    return all;
}

bool valid_name(const std::string& name) {
    if (name.empty() || name.size() > 64) return false;
    for (char c : name)
        if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-'))
            return false;
    return true;
}

/// The registry's size before the first register_structure: its first entries are rcbench's own
/// (0 while none was added).
std::size_t& own_entries() {
    static std::size_t n = 0;
    return n;
}

}  // namespace

const std::deque<StructureInfo>& structure_registry() { return registry(); }

bool rcbench_structure(std::string_view name) {
    const std::size_t own = own_entries() ? own_entries() : registry().size();
    for (std::size_t i = 0; i < own; ++i)
        if (registry()[i].name == name) return true;
    return false;
}

std::vector<std::string> structure_names(const std::function<bool(const StructureInfo&)>& keep) {
    std::vector<std::string> out;
    for (const StructureInfo& info : structure_registry())
        if (!keep || keep(info)) out.push_back(info.name);
    return out;
}

const char* origin_name(Origin origin) {
    switch (origin) {
        case Origin::thesis:
            return "thesis";
        case Origin::own:
            return "own";
        case Origin::peer:
            return "peer";
    }
    return "";
}

const char* family_name(Family family) {
    switch (family) {
        case Family::scan:
            return "scan";
        case Family::grid:
            return "grid";
        case Family::bvh:
            return "bvh";
        case Family::peer:
            return "peer";
        case Family::other:
            return "other";
    }
    return "";
}

StructureInfo with_common_params(StructureInfo info) {
    const ParamSpec query = query_param_spec();
    for (const ParamSpec& p : info.params)
        if (p.name == query.name) return info;
    info.params.push_back(query);
    info.params.push_back(leaf_bv_param_spec());
    if (info.make)
        info.make = [own_make = std::move(info.make), name = info.name, specs = info.params](
                        const nlohmann::json& params, const std::string& path) -> std::unique_ptr<Structure> {
            check_params(specs, params, path, name);
            return at_query_level(own_make(own_params(params), path), query_level_of(params), leaf_bv_of(params), path);
        };
    return info;
}

const StructureInfo& register_structure(StructureInfo info) {
    const std::string where = "register_structure(" + quoted_excerpt(info.name) + ")";
    if (!valid_name(info.name))
        throw InputError(where + ": a structure name is 1 to 64 ASCII letters, digits, '_' or '-'");
    if (info.name == "all")
        throw InputError(where + ": 'all' is reserved (rcbench simulate --structure all runs every structure)");
    for (const StructureInfo& known : registry())
        if (known.name == info.name)
            throw InputError(where + ": a structure named '" + info.name + "' is already registered (" +
                             quoted_excerpt(known.summary, 60) + ")");
    if (!info.make) throw InputError(where + ": the entry has no factory (make is empty)");
    info = with_common_params(std::move(info));
    check_params(info.params, info.defaults(), where + ": default params", info.name);
    if (own_entries() == 0) own_entries() = registry().size();
    registry().push_back(std::move(info));
    return registry().back();
}

const StructureInfo* registered_structure(std::string_view name) {
    for (const StructureInfo& info : structure_registry())
        if (info.name == name) return &info;
    return nullptr;
}

const StructureInfo& find_structure(std::string_view name) {
    if (const StructureInfo* info = registered_structure(name)) return *info;
    throw InputError("unknown structure '" + std::string(name) +
                     "' (known: " + join(structure_registry(), ", ", &StructureInfo::name) + ")");
}

nlohmann::json StructureInfo::defaults() const {
    nlohmann::json j = nlohmann::json::object();
    for (const ParamSpec& p : params) j[p.name] = p.default_value;
    return j;
}

nlohmann::json StructureInfo::complete(const nlohmann::json& params, const std::string& path) const {
    check_params(this->params, params, path, name);
    nlohmann::json j = defaults();
    if (params.is_object())
        for (const auto& [k, v] : params.items()) j[k] = v;
    for (const ParamSpec& p : this->params)
        if (!p.recorded_when_default && j.contains(p.name) && j[p.name] == p.default_value) j.erase(p.name);
    return j;
}

}  // namespace rcb
