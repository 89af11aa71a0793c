#pragma once
/// What the HTML report shows, apart from how (analysis/report.cpp renders it): the run's cells as
/// one entry per (scene, configuration) with medians over the repetitions, the run's provenance,
/// history and scene motion, and the figures each section's sentence quotes. Loaded once through
/// the results reader (runner/results_reader.h) and the analysis entry points (cost model, noise,
/// findings, query kinds); nothing here writes HTML, CSS or gnuplot. As google/benchmark's
/// compare.py keeps get_difference_report (the data) apart from print_difference_report.

#include <cmath>
#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "analysis/charts.h"
#include "analysis/cost_model.h"
#include "analysis/findings.h"
#include "analysis/noise.h"
#include "runner/history.h"
#include "runner/results_reader.h"

namespace rcb::report {

/// One (scene, configuration) of the run, medians over its repetitions.
struct Entry {
    std::string scene, category, structure, params, label;
    double objects = 0;
    double build_ms = 0, update_ms = 0, raycast_ms = 0, memory_per_object = 0;
    double hits = 0, missed = 0, extra = 0, duplicate = 0;
    /// Against the shapes' truth, summed over the measured frames of every repetition.
    double returned = 0, correct = 0, relevant = 0;
    bool verified = true;                             ///< every repetition was checked against the truth
    std::vector<double> frame_raycast_ms, frame_sah;  ///< repetition 0's frames
    /// The scene's recording and the frames it measures (runner/experiment.h, "measure"): the scene
    /// without its window ("brownian-10k" of "brownian-10k-settling") and the window as read
    /// ("settling", "frames 5.. every 2nd", or "every frame").
    std::string recording, window;
    int window_order = 0;  ///< phases in core/scene/phases.h order, then start frames, then none
    /// Per query kind of a run with kinds: the kind's batch per frame, the median over repetitions
    /// of each cell's median over its measured frames (frame_kind.raycast_ns).
    std::map<std::string, double> kind_raycast_ms;
    double total_ms() const { return update_ms + raycast_ms; }
    /// Per frame = update + ray cast, of every ray of the frame (`kind` empty) or of one kind's
    /// batch; NaN when the kind was not measured.
    double frame_ms(const std::string& kind) const {
        if (kind.empty()) return total_ms();
        const auto it = kind_raycast_ms.find(kind);
        return it == kind_raycast_ms.end() ? NAN : update_ms + it->second;
    }
    double precision() const { return returned > 0 ? correct / returned : 1.0; }
    double recall() const { return relevant > 0 ? correct / relevant : 1.0; }
    bool exact() const { return missed + extra + duplicate == 0 && precision() == 1 && recall() == 1; }
};

/// The run's provenance, the report's first paragraph.
struct RunHead {
    std::string experiment, commit, cpu, started;
    std::string binary;  ///< the program that made the run, and its build id when recorded
};

/// The ray-cast and update series of the experiment's runs up to this one (runner/history.h).
struct History {
    HistoryQuery query;  ///< the step options its reading quotes
    std::vector<HistorySeries> cast, update;
};

/// How much of a scene moves: per frame, the objects inserted, removed or moved over the scene's
/// objects (the frames of its first cell in the run; every cell of a scene replays the same frames).
struct SceneMotion {
    std::string scene;
    double p10 = 0, p50 = 0, p90 = 0;
};

/// Everything the report reads from the database.
struct ReportData {
    std::vector<Entry> entries;
    RunHead head;
    std::vector<SlowCell> slow;
    std::vector<FrameObservation> frames;
    ModelInputs model_inputs;
    NoiseFloor noise;
    std::vector<Finding> findings;
    History history;
    std::vector<SceneMotion> motion;
    std::vector<FrameObservation> kind_frames;  ///< per query kind; empty for a run without kinds
};

/// Everything the report shows of run `run` (with its sibling shards); InputError for a run
/// without measured cells.
ReportData load_report_data(Database& db, std::int64_t run);

/// Structure plus the parameters that differ from its defaults: "dbvh mode=rebuild".
std::string config_label(const std::string& structure, const std::string& params_text);

/// The distinct values of `field` over `entries`, in order of first appearance.
template <typename T>
std::vector<std::string> unique_in_order(const std::vector<Entry>& entries, T field) {
    std::vector<std::string> out;
    for (const Entry& e : entries)
        if (std::find(out.begin(), out.end(), field(e)) == out.end()) out.push_back(field(e));
    return out;
}

/// The entries with what every section asks of them.
struct Entries {
    explicit Entries(const std::vector<Entry>& entries)
        : all(entries),
          scenes(unique_in_order(entries, [](const Entry& e) { return e.scene; })),
          labels(unique_in_order(entries, [](const Entry& e) { return e.label; })),
          largest(std::max_element(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
                      return a.objects < b.objects;
                  })->scene) {}
    /// A configuration keeps its colour and marker in every chart.
    int style_of(const std::string& label) const {
        return int(std::find(labels.begin(), labels.end(), label) - labels.begin()) + 1;
    }
    const Entry* find(const std::string& scene, const std::string& label) const {
        for (const Entry& e : all)
            if (e.scene == scene && e.label == label) return &e;
        return nullptr;
    }

    const std::vector<Entry>& all;
    std::vector<std::string> scenes, labels;  ///< in order of first appearance
    std::string largest;                      ///< the scene with the most objects
};

/// The largest scene of `category`, and on it the configuration with the lowest update + ray cast
/// (configurations in label order; the first of equal ones).
std::pair<std::string, const Entry*> best_on_largest(const Entries& es, const std::string& category);

/// The configuration whose ray cast changed most from the first to the last quarter of its frames.
std::pair<std::string, double> largest_drift(const Entries& es);

/// The scene category with the most distinct object counts (more than one), or "".
std::string growth_category(const std::vector<Entry>& entries);

/// Brute force on `scene`, the baseline the thesis measures speed-ups against (§4.1; the registry's
/// family scan): its first configuration, or only its configuration at the defaults.
const Entry* baseline_on(const std::vector<Entry>& entries, const std::string& scene, bool default_params_only);

/// Comparisons against the peers: the physics section (scenes of a physics generator,
/// core/scene/generate/physics.h, each window of a recording, a phase or from a start frame, a
/// scene of its own) and, for every other scene where a peer was measured, the same comparison.
struct PeerBest {
    std::string structure;
    const Entry* entry = nullptr;  ///< the peer's fastest configuration on the scene
    double ms = NAN;
};
/// On one scene, for every ray of the frame or one query kind: the fastest own configuration
/// (rcbench's, every structure not Origin::peer) against each peer structure's fastest.
struct PeerComparison {
    const Entry* scene = nullptr;  ///< any entry of the scene, for its names
    std::string kind;              ///< "" for every ray of the frame
    const Entry* own = nullptr;
    double own_ms = NAN;
    std::vector<PeerBest> peers;  ///< per peer structure measured there, in registry order
    std::size_t best_peer = 0;    ///< index into peers (the first of equal ones)
    /// Best own over best peer per frame; NaN without a peer or an own configuration.
    double ratio() const { return own && !peers.empty() ? own_ms / peers[best_peer].ms : NAN; }
};
struct PeerSection {
    std::vector<const Entry*> entries;        ///< by scene generator, objects, recording, window, then registry order
    std::vector<std::string> kinds;           ///< query kinds measured on them, in QueryKind order
    std::vector<PeerComparison> comparisons;  ///< per scene in entries' order: every ray, then each kind
};
/// The physics scenes of `es` (no entries without any). Time per frame is Entry::frame_ms: the
/// medians over repetitions of the cells' medians, update plus ray cast.
PeerSection physics_section(const Entries& es);
/// The same for the other scenes of `es` on which a peer was measured.
PeerSection peer_section(const Entries& es);

/// One failure-mode cell against brute force and the benign scene of the same size.
struct FailureCell {
    double mismatches = 0;
    double vs_bf = NAN, vs_benign = NAN;  ///< cost ratios; NaN without the other cell or its time
};

/// `e` against brute force on its scene and against the benign scene of as many objects.
FailureCell failure_cell(const std::vector<Entry>& entries, const Entry& e);

/// The SAH cost's change from the first to the last frame of each tree on the largest scene.
struct SahChange {
    std::string label;
    double change = 0;
    Series series;
};

/// Per tree with SAH costs recorded on the largest scene, in entry order.
std::vector<SahChange> sah_changes(const Entries& es);

}  // namespace rcb::report
