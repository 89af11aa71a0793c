// Physics scenes measured per phase: the phases of one experiment entry replay one recording,
// generated once per run, with the cells a recording generated for each phase alone gives; and the
// report's physics section shows per frame = update + ray cast of every configuration per phase and
// query kind, and each scene's best own configuration against each peer's best, named.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>

#include "analysis/report.h"
#include "analysis/report_data.h"
#include "core/base/statistics.h"
#include "accel/registry.h"
#include "core/base/number_text.h"
#include "sim/simulator.h"
#include "runner/experiment.h"
#include "runner/run_experiment.h"
#include "runner/scene_windows.h"
#include "runner/sqlite.h"
#include "runner/store.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

/// A 500-body Brownian scene measured in two phases, with the game's query kinds, and a scene of
/// boxes; two own structures and two peers, one of them in two configurations; two repetitions.
const char* kExperiment = R"({"name": "physics-report", "rays_per_frame": 120, "repetitions": 2,
    "scenes": [{"generator": "brownian", "objects": 500, "frames": 24, "queries": "game",
                "phases": ["impact", "settling"], "name": "brownian-500"},
               {"generator": "uniform", "objects": 400, "frames": 5, "name": "boxes"}],
    "structures": [{"name": "dbvh"}, {"name": "wbvh"},
                   {"name": "embree", "grids": [{"quality": "low", "refit": true}, {"quality": "medium"}]},
                   {"name": "bullet_dbvt"}]})";

class PhysicsRun : public ::testing::Test {
protected:
    static void SetUpTestSuite() {
        temp_ = std::make_unique<test::TempDir>("physics_report", "run");
        db_path_ = temp_->file("r.db");
        experiment_ = std::make_unique<Experiment>(parse_experiment(kExperiment, "physics-report.json", "."));
        RunOptions options;
        options.db = db_path_;
        options.new_run = true;
        outcome_ = run_experiment(*experiment_, "physics-report.json", options);
    }
    static void TearDownTestSuite() {
        experiment_.reset();
        temp_.reset();
    }
    static std::unique_ptr<test::TempDir> temp_;
    static std::string db_path_;
    static std::unique_ptr<Experiment> experiment_;
    static RunOutcome outcome_;
};
std::unique_ptr<test::TempDir> PhysicsRun::temp_;
std::string PhysicsRun::db_path_;
std::unique_ptr<Experiment> PhysicsRun::experiment_;
RunOutcome PhysicsRun::outcome_;

/// One stored frame's counters, as the comparison with a fresh simulation reads them.
struct StoredFrame {
    std::int64_t frame = 0, warmup = 0, hits = 0, missed = 0, n_t = 0, n_rb = 0, n_tp = 0, n_th = 0;
    friend bool operator==(const StoredFrame&, const StoredFrame&) = default;
};

TEST_F(PhysicsRun, PhasesShareOneRecordingAndGiveTheCellsOfARecordingGeneratedPerPhase) {
    ASSERT_EQ(experiment_->scenes.size(), 3u);
    ASSERT_TRUE(outcome_.finished);
    EXPECT_EQ(outcome_.mismatches, 0u);
    EXPECT_EQ(outcome_.recordings, 2u) << "the two phases of one entry are one recording, generated once";
    EXPECT_EQ(recording_key(experiment_->scenes[0]), recording_key(experiment_->scenes[1]));
    EXPECT_NE(recording_key(experiment_->scenes[0]), recording_key(experiment_->scenes[2]));
    Database db(db_path_, true);
    for (const SceneSpec& scene : experiment_->scenes) {
        SCOPED_TRACE(scene.name);
        // Regenerated for this phase alone: the same bytes (the stored scene's hash) ...
        const Recording alone = load_scene(scene);
        Statement h = db.prepare("SELECT hash FROM scene WHERE name = ?");
        h.bind_all(scene.name);
        ASSERT_TRUE(h.step());
        EXPECT_EQ(h.text(0), recording_hash(alone));
        // ... and, replayed, the same frames: measured or not, hits and counters of every repetition.
        for (const ConfigSpec& config : experiment_->configs) {
            SCOPED_TRACE(config.structure + config.params.dump());
            const SimulationResult res = simulate(alone, find_structure(config.structure), config.params);
            std::vector<StoredFrame> fresh;
            for (const FrameResult& f : res.frames)
                fresh.push_back({std::int64_t(f.frame), f.warmup, std::int64_t(f.hits), std::int64_t(f.missed),
                                 std::int64_t(f.counters.n_t), std::int64_t(f.counters.n_rb),
                                 std::int64_t(f.counters.n_tp), std::int64_t(f.counters.n_th)});
            for (std::int64_t repetition : {0, 1}) {
                Statement s = db.prepare(
                    "SELECT f.frame, f.warmup, f.hits, f.missed, f.n_t, f.n_rb, f.n_tp, f.n_th FROM frame f JOIN cell "
                    "ON cell.id = f.cell_id JOIN scene ON scene.id = cell.scene_id JOIN config ON config.id = "
                    "cell.config_id WHERE scene.name = ? AND config.structure = ? AND config.params = ? AND "
                    "cell.repetition = ? ORDER BY f.frame");
                s.bind_all(scene.name, config.structure, config.params.dump(), repetition);
                std::vector<StoredFrame> stored;
                while (s.step())
                    stored.push_back({s.int64(0), s.int64(1), s.int64(2), s.int64(3), s.int64(4), s.int64(5),
                                      s.int64(6), s.int64(7)});
                EXPECT_EQ(stored.size(), alone.frames.size());
                EXPECT_TRUE(stored == fresh) << "repetition " << repetition;
            }
        }
    }
}

/// The medians the physics section must show, read here from the cells: per (scene, configuration)
/// the median over repetitions of cell.update_ns_median and cell.raycast_ns_median, and per kind of
/// each cell's median kind batch over its measured frames.
struct Expected {
    double update_ms = 0, raycast_ms = 0;
    std::map<std::string, double> kind_ms;
};
std::map<std::pair<std::string, std::string>, Expected> expected_medians(Database& db) {
    std::map<std::pair<std::string, std::string>, std::vector<double>> update, cast;
    std::map<std::pair<std::string, std::string>, std::map<std::string, std::vector<double>>> kinds;
    Statement s = db.prepare(
        "SELECT scene.name, config.structure, config.params, cell.id, cell.update_ns_median, cell.raycast_ns_median "
        "FROM cell JOIN scene ON scene.id = cell.scene_id JOIN config ON config.id = cell.config_id");
    while (s.step()) {
        const auto key = std::make_pair(s.text(0), report::config_label(s.text(1), s.text(2)));
        update[key].push_back(s.real(4) / 1e6);
        cast[key].push_back(s.real(5) / 1e6);
        Statement k = db.prepare(
            "SELECT frame_kind.kind, frame_kind.raycast_ns FROM frame_kind JOIN frame USING (cell_id, frame) WHERE "
            "frame_kind.cell_id = ? AND frame.warmup = 0");
        k.bind_all(s.int64(3));
        std::map<std::string, std::vector<double>> batches;
        while (k.step()) batches[k.text(0)].push_back(k.real(1) / 1e6);
        for (const auto& [kind, ms] : batches) kinds[key][kind].push_back(quantile(ms, 0.5));
    }
    std::map<std::pair<std::string, std::string>, Expected> out;
    for (const auto& [key, v] : update) {
        Expected& e = out[key];
        e.update_ms = quantile(v, 0.5);
        e.raycast_ms = quantile(cast[key], 0.5);
        for (const auto& [kind, ms] : kinds[key]) e.kind_ms[kind] = quantile(ms, 0.5);
    }
    return out;
}

std::string read_text(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

/// Each comparison of `p` against the medians read from the cells: the fastest own configuration,
/// each peer's fastest and the best peer, with the row of `page` that names them and the ratio.
void check_comparisons(const report::PeerSection& p,
                       const std::map<std::pair<std::string, std::string>, Expected>& expected,
                       const std::string& page) {
    for (const report::PeerComparison& c : p.comparisons) {
        SCOPED_TRACE(c.scene->scene + " " + c.kind);
        const auto frame_ms = [&](const report::Entry* e) {
            const Expected& x = expected.at({e->scene, e->label});
            return x.update_ms + (c.kind.empty() ? x.raycast_ms : x.kind_ms.at(c.kind));
        };
        std::string own, best;
        std::map<std::string, std::string> peer_best;  // structure -> label
        double own_ms = INFINITY, best_ms = INFINITY;
        std::map<std::string, double> peer_ms;
        for (const report::Entry* e : p.entries) {
            if (e->scene != c.scene->scene) continue;
            const double ms = frame_ms(e);
            if (registered_structure(e->structure)->origin != Origin::peer) {
                if (ms < own_ms) own_ms = ms, own = e->label;
                continue;
            }
            if (!peer_ms.count(e->structure) || ms < peer_ms[e->structure])
                peer_ms[e->structure] = ms, peer_best[e->structure] = e->label;
            if (ms < best_ms) best_ms = ms, best = e->label;
        }
        ASSERT_NE(c.own, nullptr);
        EXPECT_EQ(c.own->label, own);
        EXPECT_DOUBLE_EQ(c.own_ms, own_ms);
        ASSERT_EQ(c.peers.size(), 2u);
        EXPECT_EQ(c.peers[0].structure, "embree");
        EXPECT_EQ(c.peers[1].structure, "bullet_dbvt");
        for (const report::PeerBest& b : c.peers) {
            EXPECT_EQ(b.entry->label, peer_best[b.structure]);
            EXPECT_DOUBLE_EQ(b.ms, peer_ms[b.structure]);
        }
        EXPECT_EQ(c.peers[c.best_peer].entry->label, best);
        EXPECT_DOUBLE_EQ(c.ratio(), own_ms / best_ms);
        // The row names the best own, each peer's best configuration, the best peer and the ratio.
        const std::string row = "<td>" + c.scene->recording + "</td><td class=n>" + c.scene->window +
                                "</td><td class=n>" + (c.kind.empty() ? "whole frame" : c.kind + " batch") +
                                "</td><td class=n>" + own + "</td>";
        const std::size_t at = page.find(row);
        ASSERT_NE(at, std::string::npos) << row;
        const std::string rest = page.substr(at, page.find("</tr>", at) - at);
        EXPECT_NE(rest.find("<td class=n>" + peer_best["embree"] + "</td>"), std::string::npos) << rest;
        EXPECT_NE(rest.find("<td class=n>" + best + "</td><td class=n>" + fixed(own_ms / best_ms, 2) + "x</td>"),
                  std::string::npos)
            << rest;
    }
}

TEST_F(PhysicsRun, ReportShowsEachPhaseAndKindAndNamesTheBestPeerConfiguration) {
    Database db(db_path_, true);
    const report::ReportData d = report::load_report_data(db, outcome_.run);
    const report::Entries es(d.entries);
    const report::PeerSection p = report::physics_section(es);
    const auto expected = expected_medians(db);
    ASSERT_EQ(p.entries.size(), 2u * 5u);
    EXPECT_EQ(p.kinds, (std::vector<std::string>{"all", "closest", "any"}));
    // Impact before settling, each scene's configurations in registry order.
    EXPECT_EQ(p.entries.front()->window, "impact");
    EXPECT_EQ(p.entries.back()->window, "settling");
    EXPECT_EQ(p.entries.front()->structure, "dbvh");
    for (const report::Entry* e : p.entries) {
        SCOPED_TRACE(e->scene + " " + e->label);
        EXPECT_EQ(e->recording, "brownian-500");
        const Expected& x = expected.at({e->scene, e->label});
        EXPECT_DOUBLE_EQ(e->frame_ms(""), x.update_ms + x.raycast_ms);
        ASSERT_EQ(x.kind_ms.size(), 3u);
        for (const auto& [kind, ms] : x.kind_ms) EXPECT_DOUBLE_EQ(e->frame_ms(kind), x.update_ms + ms) << kind;
    }
    // Per scene: the whole frame, then each kind; the fastest own and each peer's fastest.
    ASSERT_EQ(p.comparisons.size(), 2u * 4u);
    const std::string page_path = temp_->file("r.html");
    write_report(db, outcome_.run, page_path);
    const std::string page = read_text(page_path);
    EXPECT_NE(page.find("<h2>Physics scenes: per frame, per phase, against the peers</h2>"), std::string::npos);
    check_comparisons(p, expected, page);
    std::vector<double> whole;  // best own over best peer per frame, each window
    for (const report::PeerComparison& c : p.comparisons)
        if (c.kind.empty()) whole.push_back(c.ratio());
    EXPECT_NE(page.find("Best own over best peer, whole frame: median " + fixed(quantile(whole, 0.5), 2) +
                        "x over 2 scene windows"),
              std::string::npos);
    // The scene of boxes, not a physics scene, has its comparison too: the whole frame only.
    const report::PeerSection others = report::peer_section(es);
    ASSERT_EQ(others.entries.size(), 5u);
    EXPECT_TRUE(others.kinds.empty());
    ASSERT_EQ(others.comparisons.size(), 1u);
    EXPECT_EQ(others.comparisons[0].scene->window, "every frame");
    EXPECT_NE(page.find("<h2>Against the peers</h2>"), std::string::npos);
    check_comparisons(others, expected, page);
}

}  // namespace
}  // namespace rcb
