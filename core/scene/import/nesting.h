#pragma once
/// Nesting checks made before assimp reads a model. assimp's parsers and its scene graph recurse
/// once per level of nesting (JSON arrays and objects in rapidjson, XML elements, glTF node
/// children, COLLADA <node> and <instance_node>), on the caller's stack: a few megabytes of
/// deeply nested text overflow any stack and end in SIGSEGV inside Importer::ReadFile. A node
/// graph with a cycle recurses without end, and one where nodes are shared (a glTF node that is
/// the child of two parents, COLLADA nodes instanced twice at every level) is expanded into a
/// tree exponentially larger than the file. So, before assimp sees the file:
///  - `.gltf`, and the JSON chunk of a `.glb`: JSON nesting depth, then the node hierarchy: the
///    depth of "children" chains, no cycle, and no node with two parents (glTF 2.0 §3.5.3: the
///    hierarchy is a set of disjoint strict trees);
///  - `.dae` (COLLADA): XML element depth, then the node graph with <instance_node> references
///    followed: no cycle, its depth, and the number of nodes it expands to;
///  - any other file whose text starts with '<': XML element depth; any other text file (FBX
///    ASCII, DirectX .x, ...): the depth of { } and [ ] outside double-quoted strings.
/// Binary formats other than .glb are not scanned; model.cpp runs assimp on a thread with a large
/// stack as the backstop.

#include <cstddef>
#include <string>
#include <string_view>

namespace rcb {

/// The deepest nesting accepted: JSON or XML levels, bracket levels, node hierarchy depth. Real
/// models stay far below: of the 341 models in assimp's own test set (Debian assimp-testmodels)
/// the deepest node hierarchy is 66, the deepest XML 70 elements, the deepest brackets 74 (FBX).
/// On the 8 MB main stack assimp overflowed at about 17,000 glTF and 6,700 COLLADA levels
/// (about 0.5 and 1.3 KB per level); model.cpp gives it a 256 MiB stack.
inline constexpr std::size_t kMaxModelNesting = 1000;

/// Throws InputError naming the file, the kind of nesting, where (byte offset and line, or node)
/// and the limit, when the file's nesting goes beyond kMaxModelNesting or its node graph has a
/// cycle, a shared node, or expands to more nodes than kMaxSceneObjects (scene.h).
void check_model_nesting(const std::string& path);

/// The same on text in memory; `kind` is "gltf", "glb", "dae", or "" (sniffed as above).
void check_model_nesting_text(std::string_view bytes, const std::string& name, const std::string& kind);

}  // namespace rcb
