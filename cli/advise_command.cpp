// rcbench advise: measure every structure on a user's scene and recommend the one to ship.
#include <iostream>
#include <memory>

#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "cli/table.h"
#include "core/error.h"
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
    auto accuracy = std::make_shared<std::string>("exact");
    cmd->add_option("--accuracy", *accuracy,
                    "What the recommendation must answer: exact (no mismatches at the configuration's own query "
                    "level), recall>=R or precision>=P (against the shapes; R, P in 0..1). A constraint other than "
                    "exact also measures every structure at the candidates and shapes query levels")
        ->capture_default_str();
    cmd->callback([o, accuracy] {
        AdviseOptions options = *o;
        options.accuracy = parse_accuracy(*accuracy);
        options.progress = [](const std::string& structure) { std::cerr << "measuring " << structure << " ...\n"; };
        const Advice advice = advise(options);
        const std::vector<AdviceRow>& rows = advice.rows;
        if (advice.chosen) std::cout << "Scene " << options.scene << " -> " << advice.chosen->explanation << "\n\n";
        const bool verified = options.accuracy.needs_verification();
        std::vector<std::string> header{"structure",    "parameters", "update ms", "ray cast ms",
                                        "per frame ms", "memory",     ""};
        if (verified) header.insert(header.end(), {"precision", "recall"});
        TextTable t(header);
        for (const AdviceRow& r : rows) {
            std::vector<std::string> row{r.structure,
                                         r.params,
                                         fixed(r.cost.update_ms, 4),
                                         fixed(r.cost.raycast_ms, 4),
                                         fixed(r.cost.ms, 4) + " ± " + fixed(r.cost.mad, 4),
                                         bytes_text(r.cost.memory_bytes),
                                         std::string(r.tuned ? "tuned" : "defaults") + (r.meets ? "" : ", fails")};
            if (verified)
                row.insert(row.end(), {fixed(r.cost.accuracy.precision, 3), fixed(r.cost.accuracy.recall, 3)});
            t.add(row);
        }
        t.print(std::cout);
        if (!advice.recommended)
            throw InputError(options.scene + ": no configuration meets --accuracy " + options.accuracy.text());
        const AdviceRow& best = rows[*advice.recommended];
        std::cout << "\nShip " << best.structure << " " << best.params << ": " << fixed(best.cost.ms, 4)
                  << " ms per frame (update " << fixed(best.cost.update_ms, 4) << " + ray cast "
                  << fixed(best.cost.raycast_ms, 4) << "), " << bytes_text(best.cost.memory_bytes)
                  << (verified ? ", precision " + fixed(best.cost.accuracy.precision, 3) + ", recall " +
                                     fixed(best.cost.accuracy.recall, 3)
                               : std::string())
                  << "; meets " << options.accuracy.text() << ".";
        for (std::size_t i = *advice.recommended + 1; i < rows.size(); ++i)
            if (rows[i].meets) {
                std::cout << " Runner-up: " << rows[i].structure << ", " << fixed(rows[i].cost.ms / best.cost.ms, 2)
                          << "x its cost.";
                break;
            }
        std::cout << '\n';
    });
}

}  // namespace rcb
