// rcbench tune: per scene category, the parameters that minimise C_update + N·C; reports and database rows.
#include <algorithm>
#include <iostream>
#include <memory>
#include <optional>

#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "core/base/number_text.h"
#include "tuner/run_tuning.h"

namespace rcb {

void add_tune_command(CLI::App& app) {
    struct Options {
        std::string file, db = "results/rcbench.db", out_dir = "results";
        bool exhaustive = false, derive = false;
        std::optional<std::uint64_t> seed;
        std::string accuracy = "exact";
    };
    auto o = std::make_shared<Options>();
    CLI::App* cmd =
        app.add_subcommand("tune",
                           "Tune structures' parameters per scene category (thesis eq. 5.5: update + rays a frame)\n"
                           "Tune structures' parameters per scene category, minimising update + rays x "
                           "cost per frame (thesis eq. 5.5). Mode measured: every configuration "
                           "replayed (rays counted, not timed; the update timed) and ranked by the "
                           "cost model (the machine's micro-scene "
                           "calibration, refitted on what is timed), the file's budget timing the "
                           "best-ranked; where no model exists, a pattern search with NLopt's DIRECT. "
                           "The predicted modes search the calibrated model. Writes "
                           "results/tuning-<name>.md/.json and database rows");
    cmd->add_option("file", o->file, "Tuning file (JSON; see experiments/README.md)")->required()->check(input_file());
    cmd->add_option("--db", o->db, "Results database for the tuning rows")->capture_default_str()->check(non_empty());
    cmd->add_option("--out-dir", o->out_dir, "Folder for tuning-<name>.md/.json/.svg")
        ->capture_default_str()
        ->check(non_empty());
    cmd->add_option("--seed", o->seed, "Override the file's search seed")->check(whole_number());
    cmd->add_option("--accuracy", o->accuracy,
                    "What the chosen configurations must answer: exact (no mismatches at the configuration's own "
                    "query level), recall>=R or precision>=P (against the shapes, on every scene; R, P in 0..1). A "
                    "constraint other than exact also searches the query level (candidates, boxes, shapes)")
        ->capture_default_str();
    cmd->add_flag(
        "--exhaustive", o->exhaustive,
        "Also measure every configuration of each search space twice and report the tuner's gap to the "
        "optimum, and its regret beside the search alone, random search and coordinate descent at the same "
        "budget (a tenth of the space's structures in effect timed, every timed configuration counted, and for "
        "each method the replays of the whole space that merge configurations counting alike). Every method "
        "and the optimum are chosen on the first measurement and scored on the second, taken after it, so no "
        "choice is priced by the numbers it chose on");
    cmd->add_flag("--derive-categories", o->derive,
                  "Pool the file's scenes and tune per category derived from their features (k-means on "
                  "standardised scene features, k by silhouette; see docs/database.md) instead of per category "
                  "the file names");
    cmd->callback([o] {
        const AccuracyConstraint accuracy = parse_accuracy(o->accuracy);
        TuneSpec spec = load_tune_spec(o->file);
        for (const TuneCategory& c : spec.categories)
            if (say_deprecated_keys(o->file, c.scenes)) break;
        if (o->seed) spec.seed = *o->seed;
        set_accuracy(spec, accuracy);
        // The space's size up front: parameters a file leaves out are searched at the registry's
        // levels, and --exhaustive measures every configuration of every space.
        for (const auto& [structure, dims] : spec.space) {
            std::size_t n = 1;
            std::string searched;
            for (const SearchDimension& d : dims) {
                n *= std::max<std::size_t>(1, d.levels.size());
                if (d.levels.size() > 1) searched += (searched.empty() ? "" : ", ") + d.name;
            }
            std::cout << structure << ": " << n << " configurations (" << (searched.empty() ? "none" : searched) << ")"
                      << (o->exhaustive ? ", each measured" : "") << '\n';
        }
        TuneOptions options;
        options.file = o->file, options.db = o->db, options.out_dir = o->out_dir, options.exhaustive = o->exhaustive;
        options.derive_categories = o->derive;
        options.progress = [](const std::string& category) {
            std::cout << "tuning " << category << " ..." << std::endl;
        };
        const TuneOutcome out = run_tuning(spec, options);
        if (o->derive) {
            std::cout << "derived categories (" << out.scene_categories.rule << "):\n";
            for (std::size_t i = 0; i < out.scene_categories.categories.size(); ++i)
                std::cout << "  " << out.scene_categories.categories[i].name << ": "
                          << out.scene_categories.categories[i].members.size() << " scene(s)\n";
        }
        for (const CategoryTuning& ct : out.categories) {
            std::cout << ct.category << ": " << ct.chosen.structure << " " << searched_parameters(spec, ct.chosen)
                      << "  " << fixed(ct.chosen.measured->ms, 4) << " ± " << fixed(ct.chosen.measured->mad, 4)
                      << " ms per frame";
            for (const StructureTuning& st : ct.structures)
                for (const Candidate& c : st.candidates)
                    if (c.is_default)
                        std::cout << "  (" << c.structure << " defaults " << fixed(c.measured->ms, 4) << ")";
            std::cout << (ct.rule_note.empty() ? "" : "\n  " + ct.rule_note) << '\n';
        }
        std::cout << "wrote " << out.md_path << " and " << out.json_path << '\n';
    });
}

}  // namespace rcb
