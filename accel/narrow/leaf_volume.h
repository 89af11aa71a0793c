#pragma once
/// Leaf volumes: a second parameter that the registry gives every structure and peer, `leaf_bv`
/// (thesis §7.2: tighter bounding volumes), tests a shaped object's box hit once more against a
/// tighter volume of its shape before the query level's answer (narrow_phase.h):
///
///     aabb    none (the default)
///     kdop14  the box's slabs plus four slabs normal to the cube's diagonals (1, ±1, ±1)
///     kdop18  the box's slabs plus six slabs normal to its face diagonals (1, ±1, 0), …
///     obb     an oriented box around the shape (the shape itself for an obb; a zero-thickness
///             box in a triangle's plane; along a capsule's axis)
///
/// The volumes are kept beside the structure, by uid, as the narrow phase's shapes are: the trade
/// (fewer bounding-volume false positives against a dearer test and more memory) is the same as
/// in a BVH's leaves, with one more indirection per box hit.

#include <array>

#include <nlohmann/json.hpp>

#include "accel/interface/params.h"
#include "core/base/geometry.h"
#include "core/scene/scene.h"

namespace rcb {

enum class LeafBv { aabb, kdop14, kdop18, obb };

ParamSpec leaf_bv_param_spec();
/// The volume named by `params["leaf_bv"]` (aabb when absent); `params` is already validated.
LeafBv leaf_bv_of(const nlohmann::json& params);

/// A leaf volume, tighter than an object's box: the diagonal slabs of a k-DOP (the box's own slabs are
/// the box), or an obb as a Shape. `bv` aabb: none (a box object, or a shape no tighter).
struct LeafVolume {
    LeafBv bv = LeafBv::aabb;
    std::array<float, 12> slab{};  ///< k-DOP: lo, hi per diagonal direction
    Shape obb;
};
/// The volume of `object`'s shape, rounded outward: it contains the shape.
LeafVolume leaf_volume(const Object& object, LeafBv bv);
/// Whether the segment meets the volume (intersected with `box`, the object's box).
bool segment_hits_volume(const Segment& segment, const Aabb& box, const LeafVolume& volume);

}  // namespace rcb
