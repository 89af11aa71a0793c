// rcbench categories: scene categories derived from a run's scene features (thesis §7.2), stored with the run.
#include <iostream>
#include <memory>

#include "analysis/cost_model.h"
#include "analysis/scene_categories.h"
#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "cli/table.h"
#include "core/base/number_text.h"
#include "runner/store.h"

namespace rcb {

void add_categories_command(CLI::App& app) {
    struct Options {
        std::string db, experiment;
        std::int64_t run = 0;
        std::uint64_t seed = 1;
        std::size_t max_k = 8;
    };
    auto o = std::make_shared<Options>();
    CLI::App* cmd = app.add_subcommand(
        "categories",
        "Derive scene categories from the features of a run's scenes and store them\n"
        "Derive scene categories from the features of a run's scenes (k-means on standardised features, k by "
        "silhouette) and store them with the run");
    cmd->add_option("db", o->db, "Results database")->required()->check(input_file());
    cmd->add_option("--experiment", o->experiment, "Use the newest run of this experiment (default: the newest run)")
        ->check(non_empty());
    cmd->add_option("--run", o->run, "Use this run id")->check(run_id());
    cmd->add_option("--seed", o->seed, "Seed of the k-means++ starts")->capture_default_str()->check(whole_number());
    cmd->add_option("--max-k", o->max_k, "Most categories to consider")
        ->capture_default_str()
        ->check(CLI::Range(std::size_t(1), std::size_t(64)));
    cmd->callback([o] {
        open_read_only(o->db);     // an existing results database, checked (this command does not create one)
        ResultStore store(o->db);  // migrates, so the category tables exist
        const std::int64_t run = resolve_run(store.db(), o->run, o->experiment);
        const RunCategories rc = derive_run_categories(store.db(), run, o->seed, o->max_k);
        store_run_categories(store.db(), rc);
        const SceneClustering& c = rc.clustering;
        std::cout << "run " << run << ": " << rc.scene_ids.size() << " scenes, " << c.categories.size()
                  << " categories (" << c.rule << "). Centroids: feature values with their z-scores in parentheses "
                  << "(standard deviations from the mean of the run's scenes; sd floored at the feature's noticeable "
                  << "difference):\n\n";
        TextTable t({"category", "scenes", "nearest fixed", "members"});
        for (const DerivedCategory& d : c.categories) {
            std::string members;
            for (std::size_t i : d.members) members += (members.empty() ? "" : ", ") + rc.scene_names[i];
            t.add({d.name, std::to_string(d.members.size()), d.nearest_fixed, members});
        }
        t.print(std::cout);
        std::vector<std::string> head{"feature", "mean", "sd"};
        for (const DerivedCategory& d : c.categories) head.push_back(d.name);
        TextTable f(head);
        for (std::size_t i = 0; i < kSceneFeatureCount; ++i) {
            std::vector<std::string> row{std::string(scene_feature_names()[i]), fixed(c.scaling.mean[i], 3),
                                         fixed(c.scaling.sd[i], 3)};
            for (const DerivedCategory& d : c.categories)
                row.push_back(fixed(d.centroid[i], 3) + " (" + (d.z[i] >= 0 ? "+" : "") + fixed(d.z[i], 1) + ")");
            f.add(row);
        }
        std::cout << '\n';
        f.print(std::cout);
        std::cout << "\nstored in " << o->db
                  << " (tables scene_clustering, derived_category, derived_category_scene)\n";
    });
}

}  // namespace rcb
