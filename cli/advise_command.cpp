// rcbench advise: measure every structure on a user's scene and recommend the one to ship.
#include <iostream>
#include <memory>

#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "cli/table.h"
#include "tuner/advise.h"

namespace rcb {

void add_advise_command(CLI::App& app) {
    auto o = std::make_shared<AdviseOptions>();
    CLI::App* cmd =
        app.add_subcommand("advise",
                           "Measure every registered structure on a scene (recording or boxes CSV) at its tuned or "
                           "default parameters, and recommend the one to ship");
    cmd->add_option("scene", o->scene,
                    "Recording (.rcbscene) or boxes CSV (given 10 frames of 1% dynamics and 1000 centre rays)")
        ->required()
        ->check(input_file());
    cmd->add_option("--tuning", o->tuning,
                    "A tuner's results (results/tuning-<name>.json): use its parameters for --category, or without "
                    "--category for the category whose centroid is nearest this scene's features")
        ->check(input_file());
    cmd->add_option("--category", o->category,
                    "Which category of the tuning file this scene resembles (default: chosen from the scene's "
                    "features)");
    cmd->add_option("--repetitions", o->repetitions, "Measurements per structure")
        ->capture_default_str()
        ->check(CLI::Range(1u, 100u));
    cmd->add_option("--warmup", o->warmup, "Frames left out of the medians")
        ->capture_default_str()
        ->check(whole_number(0, 1'000'000));
    cmd->callback([o] {
        AdviseOptions options = *o;
        options.progress = [](const std::string& structure) { std::cerr << "measuring " << structure << " ...\n"; };
        const Advice advice = advise(options);
        const std::vector<AdviceRow>& rows = advice.rows;
        if (advice.chosen) std::cout << "Scene " << options.scene << " -> " << advice.chosen->explanation << "\n\n";
        TextTable t({"structure", "parameters", "update ms", "ray cast ms", "per frame ms", "memory", ""});
        for (const AdviceRow& r : rows)
            t.add({r.structure, r.params, fixed(r.cost.update_ms, 4), fixed(r.cost.raycast_ms, 4),
                   fixed(r.cost.ms, 4) + " ± " + fixed(r.cost.mad, 4), bytes_text(r.cost.memory_bytes),
                   r.tuned ? "tuned" : "defaults"});
        t.print(std::cout);
        std::cout << "\nShip " << rows[0].structure << " " << rows[0].params << ": " << fixed(rows[0].cost.ms, 4)
                  << " ms per frame (update " << fixed(rows[0].cost.update_ms, 4) << " + ray cast "
                  << fixed(rows[0].cost.raycast_ms, 4) << "), " << bytes_text(rows[0].cost.memory_bytes) << ".";
        if (rows.size() > 1)
            std::cout << " Runner-up: " << rows[1].structure << ", " << fixed(rows[1].cost.ms / rows[0].cost.ms, 2)
                      << "x its cost.";
        std::cout << '\n';
    });
}

}  // namespace rcb
