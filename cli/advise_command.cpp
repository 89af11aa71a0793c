// rcbench advise: measure every structure on a user's scene and recommend the one to ship.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>

#include "core/error.h"
#include "core/json_input.h"
#include "core/registry.h"
#include "core/simulator.h"
#include "runner/cli_checks.h"
#include "runner/experiment.h"
#include "runner/table.h"
#include "tuner/commands.h"
#include "tuner/tuning.h"

namespace rcb {

void add_advise_command(CLI::App& app) {
    struct Options {
        std::string scene, tuning, category;
        std::uint32_t repetitions = 3, warmup = 1, frames = 0;
    };
    auto o = std::make_shared<Options>();
    CLI::App* cmd = app.add_subcommand("advise", "Measure every registered structure on a scene (recording or boxes CSV) at its tuned or "
                                                 "default parameters, and recommend the one to ship");
    cmd->add_option("scene", o->scene, "Recording (.rcbscene) or boxes CSV (given 10 frames of 1% dynamics and 1000 centre rays)")->required();
    cmd->add_option("--tuning", o->tuning, "A tuner's results (results/tuning-<name>.json): use its parameters for --category");
    cmd->add_option("--category", o->category, "Which category of the tuning file this scene resembles");
    cmd->add_option("--repetitions", o->repetitions, "Measurements per structure")->capture_default_str()->check(CLI::Range(1u, 100u));
    cmd->add_option("--warmup", o->warmup, "Frames left out of the medians")->capture_default_str()->check(whole_number(0, 1'000'000));
    cmd->callback([o] {
        if (o->tuning.empty() != o->category.empty()) throw InputError("--tuning and --category go together");
        std::map<std::string, nlohmann::json> tuned;
        if (!o->tuning.empty()) {
            const nlohmann::json t = parse_json_document(read_text_file(o->tuning), o->tuning);
            bool found = false;
            try {
                for (const auto& c : t.at("categories")) {
                    if (c.at("category").get<std::string>() != o->category) continue;
                    found = true;
                    for (const auto& s : c.at("structures"))
                        tuned[s.at("structure").get<std::string>()] = s.at("best").at("params");
                }
            } catch (const nlohmann::json::exception&) {  // a missing key or a value of the wrong type
                throw InputError(o->tuning + ": not a tuning result (rcbench tune writes them)");
            }
            if (!found) throw InputError(o->tuning + ": no category \"" + o->category + "\"");
        }
        TuneCategory category;
        category.name = std::filesystem::path(o->scene).stem().string();
        SceneSpec spec;
        spec.name = category.name;
        spec.path = o->scene;
        spec.key = {{"advise", o->scene}};
        const bool csv = o->scene.size() >= 4 && o->scene.compare(o->scene.size() - 4, 4, ".csv") == 0;
        spec.source = csv ? SceneSpec::Source::import : SceneSpec::Source::recording;
        if (csv) spec.settings.frames = 10;
        if (!std::filesystem::is_regular_file(o->scene)) throw InputError(o->scene + ": no such file");
        category.scenes.push_back(spec);
        try {
            check_warmup(o->warmup, recording_of(spec).frames.size());
        } catch (const InputError& e) {
            throw InputError(o->scene + ": " + e.what());
        }

        struct Row {
            std::string structure, params;
            MeasuredCost cost;
            bool tuned;
        };
        std::vector<Row> rows;
        for (const StructureInfo& info : structure_registry()) {
            const bool is_tuned = tuned.count(info.name) != 0;
            const nlohmann::json params = is_tuned ? info.complete(tuned[info.name], o->tuning) : info.defaults();
            std::cerr << "measuring " << info.name << " ...\n";
            rows.push_back({info.name, params.dump(), measure(category, info.name, params, o->warmup, o->repetitions), is_tuned});
        }
        std::sort(rows.begin(), rows.end(), [](const Row& a, const Row& b) { return a.cost.ms < b.cost.ms; });
        TextTable t({"structure", "parameters", "update ms", "ray cast ms", "per frame ms", "memory", ""});
        for (const Row& r : rows)
            t.add({r.structure, r.params, fixed(r.cost.update_ms, 4), fixed(r.cost.raycast_ms, 4),
                   fixed(r.cost.ms, 4) + " ± " + fixed(r.cost.mad, 4), bytes_text(r.cost.memory_bytes), r.tuned ? "tuned" : "defaults"});
        t.print(std::cout);
        std::cout << "\nShip " << rows[0].structure << " " << rows[0].params << ": " << fixed(rows[0].cost.ms, 4) << " ms per frame (update "
                  << fixed(rows[0].cost.update_ms, 4) << " + ray cast " << fixed(rows[0].cost.raycast_ms, 4) << "), "
                  << bytes_text(rows[0].cost.memory_bytes) << ".";
        if (rows.size() > 1)
            std::cout << " Runner-up: " << rows[1].structure << ", " << fixed(rows[1].cost.ms / rows[0].cost.ms, 2) << "x its cost.";
        std::cout << '\n';
    });
}

}  // namespace rcb
