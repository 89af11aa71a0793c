#include "tuner/advise.h"

#include <algorithm>
#include <filesystem>
#include <map>

#include "core/error.h"
#include "core/json_input.h"
#include "core/query_level.h"
#include "core/registry.h"
#include "core/simulator.h"
#include "runner/experiment.h"

namespace rcb {

CategoryChoice choose_category(const std::string& tuning, const nlohmann::json& t, const Recording& scene) {
    if (!t.is_object() || !t.contains("scene_categories"))
        throw InputError(tuning +
                         ": has no scene categories to match a scene to (written by an older rcbench tune); give "
                         "--category or tune again");
    const SceneClustering clustering = SceneClustering::from_json(t["scene_categories"], tuning);
    CategoryChoice c;
    c.features = compute_scene_features(scene);
    c.match = nearest_category(clustering, c.features);
    c.category = clustering.categories[c.match.category].name;
    c.explanation = explain_match(clustering, c.match);
    return c;
}

Advice advise(const AdviseOptions& o) {
    if (o.tuning.empty() && !o.category.empty()) throw InputError("--category needs --tuning");
    if (!std::filesystem::is_regular_file(o.scene)) throw InputError(o.scene + ": no such file");
    TuneCategory category;
    category.name = std::filesystem::path(o.scene).stem().string();
    SceneSpec spec;
    spec.name = category.name;
    spec.path = o.scene;
    spec.key = {{"advise", o.scene}};
    const bool csv = o.scene.size() >= 4 && o.scene.compare(o.scene.size() - 4, 4, ".csv") == 0;
    spec.source = csv ? SceneSpec::Source::import : SceneSpec::Source::recording;
    if (csv) spec.settings.frames = 10;
    category.scenes.push_back(spec);

    Advice advice;
    std::map<std::string, nlohmann::json> tuned;
    if (!o.tuning.empty()) {
        const nlohmann::json t = parse_json_document(read_text_file(o.tuning), o.tuning);
        std::string wanted = o.category;
        if (wanted.empty()) {
            advice.chosen = choose_category(o.tuning, t, recording_of(spec));
            wanted = advice.chosen->category;
        }
        bool found = false;
        try {
            for (const auto& c : t.at("categories")) {
                if (c.at("category").get<std::string>() != wanted) continue;
                found = true;
                for (const auto& s : c.at("structures"))
                    tuned[s.at("structure").get<std::string>()] = s.at("best").at("params");
            }
        } catch (const nlohmann::json::exception&) {  // a missing key or a value of the wrong type
            throw InputError(o.tuning + ": not a tuning result (rcbench tune writes them)");
        }
        if (!found) throw InputError(o.tuning + ": no category \"" + wanted + "\"");
    }
    try {
        check_warmup(o.warmup, recording_of(spec).frames.size());
    } catch (const InputError& e) {
        throw InputError(o.scene + ": " + e.what());
    }

    // Every structure's parameters are checked before the first measurement, so a bad tuning file
    // fails at once, not after minutes of measuring.
    std::vector<AdviceRow>& rows = advice.rows;
    std::vector<nlohmann::json> params;
    for (const StructureInfo& info : structure_registry()) {
        const bool is_tuned = tuned.count(info.name) != 0;
        // The complete parameters a result records (parameters recorded only away from their
        // default, as the query level, left out).
        params.push_back(
            info.complete(is_tuned ? tuned[info.name] : nlohmann::json::object(), is_tuned ? o.tuning : info.name));
        rows.push_back({info.name, params.back().dump(), {}, is_tuned});
        // Inexact answers allowed: the same configuration at the other query levels competes too
        // (a tuned level is kept as the tuning chose it).
        if (o.accuracy.allows_inexact() && query_level_of(params.back()) == QueryLevel::boxes)
            for (const char* level : {"candidates", "shapes"}) {
                nlohmann::json p = params.back();
                p["query"] = level;
                params.push_back(info.complete(p, "advise"));
                rows.push_back({info.name, params.back().dump(), {}, is_tuned});
            }
    }
    for (std::size_t i = 0; i < rows.size(); ++i) {
        if (o.progress) o.progress(rows[i].structure);
        rows[i].cost =
            measure(category, rows[i].structure, params[i], o.warmup, o.repetitions, o.accuracy.needs_verification());
    }
    advice.recommended = rank_advice(rows, o.accuracy);
    return advice;
}

std::optional<std::size_t> rank_advice(std::vector<AdviceRow>& rows, const AccuracyConstraint& accuracy) {
    std::stable_sort(rows.begin(), rows.end(),
                     [](const AdviceRow& a, const AdviceRow& b) { return a.cost.ms < b.cost.ms; });
    std::optional<std::size_t> best;
    for (std::size_t i = 0; i < rows.size(); ++i) {
        rows[i].meets = accuracy.met_by(rows[i].cost.accuracy);
        if (rows[i].meets && !best) best = i;
    }
    return best;
}

}  // namespace rcb
