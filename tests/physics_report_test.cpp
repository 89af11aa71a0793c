// Physics scenes measured per phase: the phases of one experiment entry replay one recording,
// generated once per run, with the cells a recording generated for each phase alone gives.
#include <gtest/gtest.h>

#include <memory>

#include "core/accel/registry.h"
#include "core/sim/simulator.h"
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
    "scenes": [{"kind": "brownian", "objects": 500, "frames": 24, "queries": "game",
                "phases": ["impact", "settling"], "name": "brownian-500"},
               {"kind": "uniform", "objects": 400, "frames": 5, "name": "boxes"}],
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

}  // namespace
}  // namespace rcb
