#pragma once
/// One entry point for every static-scene importer, chosen by the file's extension: `.csv`
/// (core/scene/import/csv.h), `.bsp` / `.pk3` (bsp.h), anything assimp reads (model.h). Used by
/// `rcbench scene import` and by experiment files' "import" scenes.

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/scene/import/bsp.h"
#include "core/scene/scene.h"

namespace rcb {

struct ImportOptions {
    std::string bsp_mode = "brushes";      ///< .bsp/.pk3: "brushes" or "triangles"
    std::string map;                       ///< .pk3 with several maps: which one
    std::string model_mode = "instances";  ///< models: "instances", "obbs" or "triangles"
    /// .bsp/.pk3 in triangles mode: the most triangles imported (bsp.h: a budget on time and memory).
    std::uint64_t bsp_max_triangles = kDefaultBspMaxTriangles;
};

/// "csv", "bsp", "broadmark" (`.aabbs`, broadmark.h) or "model"; throws InputError naming the file
/// for an extension nothing reads.
std::string importer_for(const std::string& path);

/// The file's objects (uids 0..n−1 for BSP and models, the file's for CSV). A Broadmark file is
/// refused (InputError): it is a whole recording with motion, read by read_broadmark. `meta` (if given)
/// receives what was imported and how: importer, mode, map, counts kept and skipped.
std::vector<Object> import_objects(const std::string& path, const ImportOptions& options,
                                   nlohmann::json* meta = nullptr);

/// Options from a JSON object {"bsp_mode", "map", "model_mode", "bsp_max_triangles"} (unknown keys
/// refused; `path` prefixes messages).
ImportOptions import_options_from_json(const nlohmann::json& j, const std::string& path);
/// The options as JSON; bsp_max_triangles only when it is not the default (it changes no scene,
/// only whether a large one is refused, so it stays out of the scene's identity by default).
nlohmann::json to_json(const ImportOptions& options);

}  // namespace rcb
