#include "core/registry.h"

#include "core/peers/bullet_dbvt.h"
#include "core/peers/embree_boxes.h"
#include "core/structures/brute_force.h"
#include "core/structures/dynamic_bvh.h"
#include "core/structures/linear_bvh.h"
#include "core/structures/hash_grid.h"
#include "core/structures/uniform_grid.h"

namespace rcb {

const std::vector<StructureInfo>& structure_registry() {
    static const std::vector<StructureInfo> all = {
        describe_structure<BruteForce>("bf", "brute force: every object's box tested (the baseline, thesis §4.1)"),
        describe_structure<DynamicBvh>("dbvh", "dynamic BVH: Catto/Box2D SAH insertion with branch and bound, fat boxes, rotations, optional full binned-SAH rebuilds (thesis §4.4)"),
        describe_structure<LinearBvh>("lbvh", "linear BVH: Karras 2012 Morton codes, radix sort, parallel radix tree, atomic bottom-up bounds, rebuilt every frame (thesis §4.5)"),
        describe_structure<UniformGrid>("ug", "uniform grid: cells from eq. 4.1, 3D-DDA with mailboxes, incremental updates (thesis §4.2)"),
        describe_structure<HashGrid>("hg", "hierarchical hash grid: Jevans-style recursive grids, only non-empty cells hashed (thesis §4.3)"),
        describe_structure<EmbreeBoxes>("embree", "peer: Intel Embree 3 user geometry of boxes, all hits recorded in the intersect callback, rebuilt (Morton or binned SAH) or refitted at commit"),
        describe_structure<BulletDbvt>("bullet_dbvt", "peer: Bullet's btDbvt, incremental insert/update/remove, optimizeIncremental passes per frame, rayTestInternal with exact leaf tests"),
    };
    return all;
}

const StructureInfo& find_structure(std::string_view name) {
    for (const StructureInfo& info : structure_registry())
        if (info.name == name) return info;
    throw InputError("unknown structure '" + std::string(name) + "' (known: " + join(structure_registry(), ", ", &StructureInfo::name) + ")");
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
    return j;
}

}  // namespace rcb
