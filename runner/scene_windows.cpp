#include "runner/scene_windows.h"

#include <cstdint>
#include <filesystem>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/import/csv.h"
#include "core/scene/import/scene_import.h"
#include "core/scene/phases.h"
#include "core/scene/recording_io.h"

namespace rcb {
namespace fs = std::filesystem;
using json = nlohmann::json;

std::string measured_meta(const SceneSpec& s, const Recording& r) {
    if (!s.key.contains("measure")) return r.meta;
    const json& m = s.key["measure"];
    json meta = json::parse(r.meta, nullptr, false);
    if (!meta.is_object()) meta = json::object();
    const auto frames = std::uint32_t(r.frames.size());
    json window = m;
    if (m.contains("phase")) {
        const std::vector<MotionPhase> phases = motion_phases(r);
        std::string found;
        for (const MotionPhase& p : phases) {
            found += (found.empty() ? "" : ", ") + p.name + " " +
                     (p.empty() ? "none" : std::to_string(p.first) + ".." + std::to_string(p.last));
            if (p.name != m["phase"]) continue;
            window["first"] = p.first, window["last"] = p.last;
        }
        if (window["first"].get<std::uint32_t>() > window["last"].get<std::uint32_t>())
            throw InputError(s.where + ": scene " + s.name + ": its recording has no " + m["phase"].get<std::string>() +
                             " phase (its phases: " + found + ")");
    } else {
        window["first"] = m["start_frame"], window["last"] = frames;
        if (m["start_frame"].get<std::uint32_t>() > frames)
            throw InputError(s.where + ".start_frame: " + m["start_frame"].dump() + " is past the scene's " +
                             std::to_string(frames) + " frames (scene " + s.name + ")");
    }
    meta["measure"] = window;
    return meta.dump();
}

std::string recording_key(const SceneSpec& s) {
    json key = s.key;
    key.erase("measure");
    return key.dump() + "|" + s.path;
}

Recording load_scene_frames(const SceneSpec& s) {
    switch (s.source) {
        case SceneSpec::Source::recording:
            return read_recording(s.path);
        case SceneSpec::Source::import: {
            if (importer_for(s.path) != "csv") {
                json meta;
                std::vector<Object> objects =
                    import_objects(s.path, import_options_from_json(s.import_options, s.path), &meta);
                if (objects.empty()) throw InputError(s.path + ": no objects to import");
                meta["generator"] = "rcbench import";
                return add_dynamics(std::move(objects), s.settings.dynamics, s.settings.rays, s.settings.frames,
                                    s.settings.seed, meta);
            }
            std::vector<Object> objects = read_boxes_csv(s.path);
            if (objects.empty()) throw InputError(s.path + ": no boxes to import");
            const json meta = {{"generator", "rcbench import"}, {"source", fs::path(s.path).filename().string()}};
            return add_dynamics(std::move(objects), s.settings.dynamics, s.settings.rays, s.settings.frames,
                                s.settings.seed, meta);
        }
        case SceneSpec::Source::generated:
            return generate_scene(s.settings);
    }
    return {};
}

}  // namespace rcb
