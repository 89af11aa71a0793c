#include "core/scene/import/scene_import.h"

#include <cctype>
#include <filesystem>

#include "core/scene/import/csv.h"
#include "core/base/error.h"
#include "core/scene/import/bsp.h"
#include "core/scene/import/model.h"

namespace rcb {

std::string importer_for(const std::string& path) {
    std::string ext = std::filesystem::path(path).extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    if (ext == ".csv") return "csv";
    if (ext == ".bsp" || ext == ".pk3") return "bsp";
    if (ext == ".aabbs") return "broadmark";
    if (is_model_extension(ext)) return "model";
    throw InputError(
        path + ": cannot import " + quoted_excerpt(ext) +
        " files (known: .csv, .bsp, .pk3 and the model formats assimp reads: .obj, .gltf, .glb, .fbx, .dae, .ply, …)");
}

std::vector<Object> import_objects(const std::string& path, const ImportOptions& options, nlohmann::json* meta) {
    const std::string kind = importer_for(path);
    if (kind == "broadmark")
        throw InputError(path +
                         ": a Broadmark scene carries its own motion: make a recording of it with `rcbench scene "
                         "import " +
                         std::filesystem::path(path).filename().string() +
                         " -o FILE.rcbscene` and name that as a \"recording\" scene");
    nlohmann::json m = {{"importer", kind}, {"source", std::filesystem::path(path).filename().string()}};
    std::vector<Object> objects;
    if (kind == "csv") {
        objects = read_boxes_csv(path);
    } else if (kind == "bsp") {
        BspSummary s;
        objects = import_bsp(path, BspOptions{options.bsp_mode, options.map, options.bsp_max_triangles}, &s);
        m["mode"] = options.bsp_mode;
        m["map"] = s.map;
        if (options.bsp_mode == "brushes")
            m["brushes"] = {{"all", s.brushes},
                            {"solid", s.solid_brushes},
                            {"skipped_non_solid", s.skipped_non_solid},
                            {"skipped_not_closed", s.skipped_not_closed}};
        else
            m["surfaces"] = s.surfaces;
    } else {
        ModelSummary s;
        objects = import_model(path, options.model_mode, &s);
        m["mode"] = options.model_mode;
        m["meshes"] = s.meshes;
        m["instances"] = s.instances;
    }
    m["objects"] = objects.size();
    if (meta) *meta = std::move(m);
    return objects;
}

ImportOptions import_options_from_json(const nlohmann::json& j, const std::string& path) {
    ImportOptions o;
    if (j.is_null()) return o;
    if (!j.is_object())
        throw InputError(path + ": expected an object with bsp_mode, map, model_mode, bsp_max_triangles");
    for (const auto& [k, v] : j.items()) {
        if (k == "bsp_max_triangles") {
            std::uint64_t n = 0;
            if (v.is_number_unsigned())
                n = v.get<std::uint64_t>();
            else if (v.is_number_integer() && v.get<std::int64_t>() > 0)
                n = std::uint64_t(v.get<std::int64_t>());
            if (n < 1 || n > kMaxSceneObjects)
                throw InputError(path + "." + k + ": expected a whole number from 1 to " +
                                 std::to_string(kMaxSceneObjects) + ", got " + quoted_excerpt(v.dump()));
            o.bsp_max_triangles = n;
            continue;
        }
        if (k != "bsp_mode" && k != "map" && k != "model_mode")
            throw InputError(path + ": unknown key " + quoted_excerpt(k) +
                             " (known: bsp_mode, map, model_mode, bsp_max_triangles)");
        if (!v.is_string()) throw InputError(path + "." + k + ": expected a string, got " + quoted_excerpt(v.dump()));
    }
    o.bsp_mode = j.value("bsp_mode", o.bsp_mode);
    o.map = j.value("map", o.map);
    o.model_mode = j.value("model_mode", o.model_mode);
    if (o.bsp_mode != "brushes" && o.bsp_mode != "triangles")
        throw InputError(path + ".bsp_mode: expected \"brushes\" or \"triangles\", got " + quoted_excerpt(o.bsp_mode));
    if (o.model_mode != "instances" && o.model_mode != "obbs" && o.model_mode != "triangles")
        throw InputError(path + ".model_mode: expected \"instances\", \"obbs\" or \"triangles\", got " +
                         quoted_excerpt(o.model_mode));
    return o;
}

nlohmann::json to_json(const ImportOptions& o) {
    nlohmann::json j = {{"bsp_mode", o.bsp_mode}, {"map", o.map}, {"model_mode", o.model_mode}};
    if (o.bsp_max_triangles != kDefaultBspMaxTriangles) j["bsp_max_triangles"] = o.bsp_max_triangles;
    return j;
}

}  // namespace rcb
