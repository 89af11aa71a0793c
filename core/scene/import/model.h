#pragma once
/// Models through assimp (Debian libassimp): anything it reads (glTF, OBJ, FBX, COLLADA, PLY, …).
///
/// Modes:
///  - `instances`: one object per mesh instance: every (node, mesh) pair of the node hierarchy,
///    its box over the mesh's vertices transformed to world space by the node's accumulated
///    transform (a mesh referenced by two nodes gives two objects).
///  - `triangles`: one object per triangle of every mesh instance, in world space. Point and line
///    primitives are skipped (they bound no surface).
/// Errors name the file and assimp's message: "ship.glb: assimp: '…'".
///
/// Before assimp reads the file, check_model_nesting (nesting.h) refuses nesting deeper than
/// kMaxModelNesting and node graphs with cycles or exponential sharing; assimp then runs on a
/// thread with a 256 MiB stack (its parsers recurse). rcbench's own walk of the node hierarchy uses
/// an explicit stack. Objects are counted before they are allocated, and more than
/// kMaxSceneObjects (scene.h) is refused; every box is checked against the coordinate limit
/// (check_object, recording_io.h).

#include <string>
#include <vector>

#include "core/scene/scene.h"

namespace rcb {

struct ModelSummary {
    std::size_t meshes = 0, instances = 0, triangles = 0;
};

std::vector<Object> import_model(const std::string& path, const std::string& mode, ModelSummary* summary = nullptr);

/// The file extensions assimp reads here (lower case, with the dot).
bool is_model_extension(const std::string& extension);

}  // namespace rcb
