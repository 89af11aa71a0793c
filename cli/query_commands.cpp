// rcbench query | compare | merge: reading, comparing and combining results databases.
#include <cmath>
#include <iostream>
#include <map>
#include <memory>

#include "core/base/error.h"
#include "core/base/output_file.h"
#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "analysis/statistics.h"
#include "runner/compare.h"
#include "runner/merge.h"
#include "runner/query.h"
#include "runner/store.h"
#include "cli/table.h"

namespace rcb {
namespace {

std::string csv_field(const std::string& s) {
    if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
    std::string q = "\"";
    for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
    return q + "\"";
}

void run_query(const std::string& path, const std::string& sql, bool csv) {
    auto db = open_read_only(path);
    QueryResult result = read_only_query(*db, sql);
    if (csv) {
        auto line = [](const std::vector<std::string>& r) {
            std::string l;
            for (std::size_t i = 0; i < r.size(); ++i) l += (i ? "," : "") + csv_field(r[i]);
            return l;
        };
        std::cout << line(result.columns) << '\n';
        for (const auto& r : result.rows) std::cout << line(r) << '\n';
        return;
    }
    TextTable t(result.columns);
    for (auto& r : result.rows) t.add(std::move(r));
    t.print(std::cout);
}

/// How far two runs of one experiment are apart, per metric: |candidate − baseline| / their mean
/// over the scene × configuration cells, median, 90th percentile and worst (two runs of one
/// experiment on one machine: the repeatability docs/architecture.md reports).
void print_run_difference(const std::vector<Comparison>& rows) {
    for (const std::string metric : {"raycast", "update"}) {
        std::vector<double> d;
        for (const Comparison& r : rows) {
            const double mean = 0.5 * (r.baseline_median + r.candidate_median);
            if (r.metric == metric && mean > 0) d.push_back(std::abs(r.candidate_median - r.baseline_median) / mean);
        }
        if (d.empty()) continue;
        std::cout << metric << ": per-cell difference |candidate - baseline| / mean over " << d.size() << " cells: p50 "
                  << fixed(100 * quantile(d, 0.5), 1) << "%, p90 " << fixed(100 * quantile(d, 0.9), 1) << "%, worst "
                  << fixed(100 * quantile(d, 1.0), 1) << "%\n";
    }
}

}  // namespace

void add_query_commands(CLI::App& app) {
    struct QueryOptions {
        std::string db, sql;
        bool csv = false;
    };
    auto q = std::make_shared<QueryOptions>();
    CLI::App* query =
        app.add_subcommand("query", "Run a read-only SQL statement on a results database (schema: docs/database.md)");
    query->add_option("db", q->db, "Results database")->required()->check(input_file());
    query->add_option("sql", q->sql, "SQL, e.g. \"" + std::string(kQueryExample) + "\"")->required();
    query->add_flag("--csv", q->csv, "Print CSV instead of a table");
    query->callback([q] { run_query(q->db, q->sql, q->csv); });

    struct CompareOptions {
        std::string db, baseline, candidate;
        std::string metric = "raycast";
        double alpha = 0.05;
        double fail_pct = -1;
    };
    auto c = std::make_shared<CompareOptions>();
    CLI::App* compare = app.add_subcommand(
        "compare",
        "Compare two runs per scene and configuration: ratio of median frame times, Mann-Whitney U p-value, verdict");
    compare->add_option("db", c->db, "Results database")->required()->check(input_file());
    compare->add_option("--baseline", c->baseline, "Run id or git commit prefix")->required();
    compare->add_option("--candidate", c->candidate, "Run id or git commit prefix")->required();
    compare->add_option("--metric", c->metric, "raycast, update or both")
        ->capture_default_str()
        ->check(CLI::IsMember({"raycast", "update", "both"}));
    compare->add_option("--alpha", c->alpha, "Significance level of the U test")
        ->capture_default_str()
        ->check(finite_range(1e-9, 0.5));
    compare
        ->add_option("--fail-on-regression", c->fail_pct,
                     "Exit 1 when a significant slowdown exceeds this many percent")
        ->check(finite_range(0.0, 1e6));
    compare->callback([c] {
        auto db = open_read_only(c->db);
        const std::vector<Comparison> rows = compare_runs(*db, c->baseline, c->candidate, c->metric, c->alpha);
        TextTable t({"scene", "structure", "params", "metric", "baseline ms", "candidate ms", "ratio", "p", "verdict",
                     "slow cells"});
        std::size_t regressions = 0;
        for (const Comparison& r : rows) {
            t.add({r.scene, r.structure, r.params, r.metric, fixed(r.baseline_median / 1e6, 4),
                   fixed(r.candidate_median / 1e6, 4), fixed(r.ratio, 3),
                   std::isnan(r.p_value) ? "-" : fixed(r.p_value, 4), r.verdict,
                   r.baseline_slow + r.candidate_slow == 0
                       ? ""
                       : std::to_string(r.baseline_slow) + "/" + std::to_string(r.candidate_slow)});
            if (c->fail_pct >= 0 && r.verdict == "slower" && (r.ratio - 1) * 100 > c->fail_pct) ++regressions;
        }
        t.print(std::cout);
        print_run_difference(rows);
        if (regressions)
            throw std::runtime_error(std::to_string(regressions) + " significant slowdowns above " +
                                     fixed(c->fail_pct, 1) + "%");
    });

    struct MergeOptions {
        std::string out;
        std::vector<std::string> in;
    };
    auto m = std::make_shared<MergeOptions>();
    CLI::App* merge = app.add_subcommand(
        "merge",
        "Combine results databases (e.g. shards) into one; runs already present are skipped. Measurements "
        "are copied; fits, validations, tunings and derived categories are not (they describe the input's "
        "cells alone): fit the merged runs again");
    merge->add_option("out", m->out, "Database to merge into (created if missing)")->required();
    merge->add_option("in", m->in, "Databases to merge from")->required()->check(input_file());
    merge->callback([m] {
        // Every input is opened (and so checked) before the output is created or touched.
        std::vector<std::unique_ptr<Database>> inputs;
        for (const std::string& in : m->in) {
            if (same_file(in, m->out)) throw InputError(in + ": cannot merge a database into itself");
            inputs.push_back(open_read_only(in));
        }
        ResultStore out(m->out);
        for (std::size_t i = 0; i < inputs.size(); ++i) {
            const MergeCount n = merge_into(out, *inputs[i]);
            std::cout << m->in[i] << ": " << n.runs << " new runs, " << n.cells << " new cells merged";
            if (n.analyses > 0)
                std::cout << "; its " << n.analyses
                          << " fits, validations and derived categories are not copied (they describe its cells "
                             "alone): rcbench fit "
                          << m->out << " --run ID for each merged run";
            std::cout << '\n';
        }
    });
}

}  // namespace rcb
