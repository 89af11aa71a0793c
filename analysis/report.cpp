#include "analysis/report.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>
#include <tuple>

#include <nlohmann/json.hpp>

#include "analysis/charts.h"
#include "analysis/cost_model.h"
#include "analysis/findings.h"
#include "analysis/noise.h"
#include "analysis/query_kinds.h"
#include "analysis/report_data.h"
#include "core/base/statistics.h"
#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/base/output_file.h"
#include "accel/registry.h"
#include "sim/simulator.h"
#include "core/base/number_text.h"
#include "runner/history.h"
#include "runner/results_reader.h"

namespace rcb {
namespace {

using namespace report;

/// Text as HTML: the characters markup gives a meaning as entities.
std::string html_escape(const std::string& s) {
    std::string out;
    for (char c : s)
        out += c == '<' ? "&lt;" : c == '>' ? "&gt;" : c == '&' ? "&amp;" : c == '"' ? "&quot;" : std::string(1, c);
    return out;
}

// ---------------------------------------------------------------------------------------------
// HTML: one function per section of the report.

class Html {
public:
    void heading(const std::string& text, int level = 2) {
        out_ << "<h" << level << ">" << html_escape(text) << "</h" << level << ">\n";
    }
    void paragraph(const std::string& text) { out_ << "<p>" << html_escape(text) << "</p>\n"; }
    void table(const std::vector<std::string>& header, const std::vector<std::vector<std::string>>& rows,
               const std::string& caption) {
        out_ << "<table><caption>" << html_escape(caption) << "</caption><tr>";
        for (const std::string& h : header) out_ << "<th>" << html_escape(h) << "</th>";
        out_ << "</tr>\n";
        for (const auto& row : rows) {
            out_ << "<tr>";
            for (std::size_t i = 0; i < row.size(); ++i)
                out_ << (i ? "<td class=n>" : "<td>") << html_escape(row[i]) << "</td>";
            out_ << "</tr>\n";
        }
        out_ << "</table>\n";
        ++tables_;
    }
    void chart(const Chart& c) {
        out_ << "<figure class=chart>" << render_svg(c) << "<figcaption>" << html_escape(c.reading)
             << "</figcaption></figure>\n";
        ++charts_;
    }
    std::string str() const { return out_.str(); }
    std::size_t charts() const { return charts_; }
    std::size_t tables() const { return tables_; }

private:
    std::ostringstream out_;
    std::size_t charts_ = 0, tables_ = 0;
};

/// Thesis Tables 6.1 and 6.2, and memory: configurations × scenes.
void tables_section(Html& h, const Entries& es, const std::vector<SlowCell>& slow_cells) {
    h.heading("Build and execution (thesis Tables 6.1 and 6.2)");
    std::set<std::pair<std::string, std::string>> slow;  // (scene, configuration) with a slow repetition
    for (const SlowCell& sc : slow_cells) slow.insert({sc.scene, config_label(sc.structure, sc.params)});
    std::vector<std::string> header{"configuration"};
    header.insert(header.end(), es.scenes.begin(), es.scenes.end());
    std::vector<std::vector<std::string>> build, cast, memory;
    for (const std::string& l : es.labels) {
        std::vector<std::string> b{l}, c{l}, m{l};
        for (const std::string& sc : es.scenes) {
            const Entry* e = es.find(sc, l);
            b.push_back(e ? format_ms(e->build_ms) : "-");
            c.push_back(e ? format_ms(e->raycast_ms) + " (" + format_ms(e->update_ms) + ")" +
                                (slow.count({sc, l}) ? " *" : "")
                          : "-");
            m.push_back(e ? fixed(e->memory_per_object, 0) : "-");
        }
        build.push_back(b), cast.push_back(c), memory.push_back(m);
    }
    h.table(header, build, "Build time (ms), Table 6.1");
    h.table(header, cast,
            std::string("Ray cast per frame (ms), with update per frame in parentheses, Table 6.2") +
                (slow.empty() ? "" : "; * a repetition was measured on a slow machine (cell_state.slow)"));
    h.table(header, memory, "Memory after the build (bytes per object)");
}

/// One line per scene: the share of its objects inserted, removed or moved per frame.
void motion_lines(Html& h, const std::vector<SceneMotion>& motion) {
    for (const SceneMotion& m : motion)
        h.paragraph("Motion on " + m.scene + ": " + fixed(100 * m.p50, 2) + "% of the objects change per frame (p10 " +
                    fixed(100 * m.p10, 2) + "%, p90 " + fixed(100 * m.p90, 2) +
                    "%; inserts, removes and moves over "
                    "the scene's objects).");
}

/// Query kinds (docs/model.md, "Query kinds: one set of coefficients"): per scene with closest or
/// any rays, configuration and kind, the time per query measured and as the run's model prices
/// the kind's own counters, and how much faster closest and any are than all hits.
void query_kinds_section(Html& h, const std::vector<KindCell>& all_cells) {
    std::set<std::string> kind_scenes;  // scenes with a kind other than all
    for (const KindCell& c : all_cells)
        if (c.kind != kQueryKindNames[0]) kind_scenes.insert(c.scene);
    if (kind_scenes.empty()) return;
    h.heading("Query kinds");
    std::vector<const KindCell*> cells;
    for (const KindCell& c : all_cells)
        if (kind_scenes.count(c.scene)) cells.push_back(&c);
    const auto find = [&](const KindCell& like, const char* kind) -> const KindCell* {
        for (const KindCell* c : cells)
            if (c->scene == like.scene && c->structure == like.structure && c->params == like.params && c->kind == kind)
                return c;
        return nullptr;
    };
    std::map<std::string, std::set<std::string>> scene_query_kinds;
    for (const KindCell* c : cells) scene_query_kinds[c->scene].insert(c->kind);
    std::vector<std::vector<std::string>> rows;
    for (const KindCell* c : cells) {
        const KindCell* all = find(*c, kQueryKindNames[0]);
        const bool three = scene_query_kinds[c->scene].size() == std::size_t(kQueryKinds);
        const bool faster = three && all && c->kind != kQueryKindNames[0] && c->ns_per_query > 0;
        rows.push_back({c->scene, config_label(c->structure, c->params), c->kind, fixed(c->rays, 0),
                        format_us(c->ns_per_query / 1e3), format_us(c->predicted_ns_per_query / 1e3),
                        std::isfinite(c->error) ? fixed(100 * c->error, 1) + "%" : "-",
                        faster ? fixed(all->ns_per_query / c->ns_per_query, 2) + "x" : "-"});
    }
    h.table({"scene", "configuration", "query kind", "rays per frame", "measured us per query",
             "predicted us per query", "error", "speed-up against all"},
            rows,
            "Per query kind: each kind's rays are cast as a batch of their own (medians over measured frames, "
            "repetitions pooled). Predicted: the run's chosen ray-cast model (fitted on whole frames) on the kind's "
            "own counters. Error: |predicted - measured| / measured of the batch per frame. Speed-up: time per "
            "all-hits query over time per query of the kind, where the scene asks all three kinds");
    std::vector<std::vector<std::string>> summary;
    for (const KindError& e : kind_errors(all_cells))
        summary.push_back({e.structure, e.kind, std::to_string(e.cells),
                           std::isfinite(e.median_error) ? fixed(100 * e.median_error, 1) + "%" : "-"});
    h.table({"structure", "query kind", "cells", "median error"}, summary,
            "One set of coefficients for every kind: median over (scene x configuration) cells of the error above, "
            "per structure and kind (all: whole frames of scenes without other kinds included). A kind whose error "
            "stands out costs per counted step what the model does not price");
}

/// The rays a physics comparison times: the whole frame or one query kind's batch.
std::string rays_name(const std::string& kind) { return kind.empty() ? "whole frame" : kind + " batch"; }

/// Physics scenes (analysis/report_data.h, PeerSection): per scene window and configuration the
/// time per frame, whole and per query kind.
void physics_times(Html& h, const PeerSection& p) {
    std::vector<std::string> header{"scene", "window", "configuration", "update", "ray cast", "per frame"};
    for (const std::string& k : p.kinds) header.push_back("per frame, " + rays_name(k));
    std::vector<std::vector<std::string>> rows;
    for (const Entry* e : p.entries) {
        std::vector<std::string> row{e->recording,
                                     e->window,
                                     e->label,
                                     format_ms(e->update_ms),
                                     format_ms(e->raycast_ms),
                                     format_ms(e->total_ms())};
        for (const std::string& k : p.kinds)
            row.push_back(std::isfinite(e->frame_ms(k)) ? format_ms(e->frame_ms(k)) : "-");
        rows.push_back(std::move(row));
    }
    h.table(header, rows,
            "Time per frame (ms) = update + ray cast: medians over the repetitions of each cell's median over the "
            "window's measured frames (every frame replays; only the window's are measured, core/scene/phases.h)" +
                std::string(p.kinds.empty() ? ""
                                            : ". Per kind: the frame's update plus that kind's batch of rays, "
                                              "cast on its own"));
}

/// Per scene and rays: the best own configuration against each peer's best, named.
void peer_comparisons(Html& h, const PeerSection& p) {
    std::vector<std::string> peers;  // every peer structure measured, in the comparisons' order
    for (const PeerComparison& c : p.comparisons)
        for (const PeerBest& b : c.peers)
            if (std::find(peers.begin(), peers.end(), b.structure) == peers.end()) peers.push_back(b.structure);
    if (peers.empty()) {
        h.paragraph("No peer structure was measured on these scenes: nothing to compare against.");
        return;
    }
    std::vector<std::string> header{"scene", "window", "rays", "best own", "ms"};
    for (const std::string& peer : peers) header.insert(header.end(), {"best " + peer, "ms"});
    header.insert(header.end(), {"best peer", "own / best peer"});
    std::vector<std::vector<std::string>> rows;
    std::vector<std::pair<std::string, std::vector<double>>> ratios;  // per rays: whole frame, then each kind
    for (const PeerComparison& c : p.comparisons) {
        std::vector<std::string> row{c.scene->recording, c.scene->window, rays_name(c.kind), c.own ? c.own->label : "-",
                                     c.own ? format_ms(c.own_ms) : "-"};
        for (const std::string& peer : peers) {
            const auto b =
                std::find_if(c.peers.begin(), c.peers.end(), [&](const PeerBest& x) { return x.structure == peer; });
            row.push_back(b == c.peers.end() ? "-" : b->entry->label);
            row.push_back(b == c.peers.end() ? "-" : format_ms(b->ms));
        }
        const bool paired = std::isfinite(c.ratio());
        row.push_back(c.peers.empty() ? "-" : c.peers[c.best_peer].entry->label);
        row.push_back(paired ? fixed(c.ratio(), 2) + "x" : "-");
        rows.push_back(std::move(row));
        const auto of_rays =
            std::find_if(ratios.begin(), ratios.end(), [&](const auto& r) { return r.first == rays_name(c.kind); });
        if (!paired) continue;
        if (of_rays == ratios.end())
            ratios.push_back({rays_name(c.kind), {c.ratio()}});
        else
            of_rays->second.push_back(c.ratio());
    }
    h.table(header, rows,
            "Per scene window and rays: rcbench's fastest configuration against each peer's fastest configuration on "
            "that window (its parameters named), per frame = update + ray cast of the whole frame or of one kind's "
            "batch (ms); own / best peer below 1: rcbench's is faster");
    for (const auto& [rays, r] : ratios)
        h.paragraph("Best own over best peer, " + rays + ": median " + fixed(quantile(r, 0.5), 2) + "x over " +
                    std::to_string(r.size()) + (r.size() == 1 ? " scene window" : " scene windows") + " (from " +
                    fixed(*std::min_element(r.begin(), r.end()), 2) + "x to " +
                    fixed(*std::max_element(r.begin(), r.end()), 2) + "x).");
}

/// The physics section, then the other scenes' comparisons against the peers (their times are in
/// Table 6.2); each nothing for a run without such scenes.
void peer_sections(Html& h, const Entries& es) {
    if (const PeerSection p = physics_section(es); !p.entries.empty()) {
        h.heading("Physics scenes: per frame, per phase, against the peers");
        physics_times(h, p);
        peer_comparisons(h, p);
    }
    if (const PeerSection p = peer_section(es); !p.entries.empty()) {
        h.heading("Against the peers");
        peer_comparisons(h, p);
    }
}

/// Whether no other configuration on `e`'s scene has both less update and less ray cast per frame
/// (one of them strictly): `e` is on its scene's front, the choices worth naming.
bool on_scene_front(const Entries& es, const Entry& e) {
    for (const Entry& f : es.all)
        if (&f != &e && f.scene == e.scene && f.update_ms <= e.update_ms && f.raycast_ms <= e.raycast_ms &&
            (f.update_ms < e.update_ms || f.raycast_ms < e.raycast_ms))
            return false;
    return true;
}

/// Update against ray cast (thesis Figures 6.1 and 6.2), one chart per scene category. A point's
/// colour and marker name its configuration (the legend); only the points on their scene's front
/// carry the scene's name, so a chart of many configurations and scenes stays readable.
void update_raycast_section(Html& h, const Entries& es) {
    h.heading("Update against ray cast (thesis Figures 6.1 and 6.2)");
    for (const std::string& category : unique_in_order(es.all, [](const Entry& e) { return e.category; })) {
        Chart c;
        c.title = "Update and ray cast per frame, " + category + " scenes";
        c.x_label = "update per frame (ms)";
        c.y_label = "ray cast per frame (ms)";
        c.log_x = c.log_y = true;
        for (const std::string& l : es.labels) {
            Series s{l, {}, {}, {}, false, es.style_of(l)};
            for (const Entry& e : es.all)
                if (e.category == category && e.label == l) {
                    s.x.push_back(std::max(e.update_ms, 1e-5));
                    s.y.push_back(e.raycast_ms);
                    s.labels.push_back(on_scene_front(es, e) ? e.scene : "");
                }
            c.series.push_back(s);
        }
        const auto [best_scene, best] = best_on_largest(es, category);
        const Entry* bf = baseline_on(es.all, best_scene, true);
        c.reading = best ? "Lower left is better. On " + best_scene + ", the lowest update + ray cast per frame is " +
                               best->label + " at " + format_ms(best->total_ms()) + " ms" +
                               (bf && best != bf
                                    ? ", " + fixed(bf->total_ms() / best->total_ms(), 1) + "x less than brute force"
                                    : "") +
                               ". Named points: each scene's front (no other configuration on the scene "
                               "has both less update and less ray cast)."
                         : "No data.";
        h.chart(c);
    }
}

/// Time per frame against precision and against recall on one scene, with the Pareto front named.
void tradeoff_charts(Html& h, const Entries& es, const std::string& sc, const std::vector<const Entry*>& here) {
    const int front_style = int(es.labels.size()) + 1;
    // A measure at 1 for every configuration would draw a flat chart: the other's reading says so.
    auto all_one = [&](bool precision) {
        return std::all_of(here.begin(), here.end(),
                           [&](const Entry* e) { return (precision ? e->precision() : e->recall()) == 1; });
    };
    for (const char* measure : {"precision", "recall"}) {
        const bool is_precision = std::string(measure) == "precision";
        if (all_one(is_precision)) continue;
        std::vector<TradeoffPoint> points;
        for (const Entry* e : here)
            points.push_back({e->label, e->total_ms(), is_precision ? e->precision() : e->recall()});
        const std::vector<std::size_t> front = pareto_front(points);
        Chart c;
        c.title = "Time per frame against " + std::string(measure) + " on " + sc;
        c.x_label = "update + ray cast per frame, narrow phase included (ms)";
        c.y_label = std::string(measure) + " against the shapes";
        c.log_x = true;
        double lowest = 1;
        for (const TradeoffPoint& p : points) lowest = std::min(lowest, p.accuracy);
        c.extra = "set yrange [" + fixed(std::max(0.0, lowest - 0.05), 2) + ":1.02]";
        for (const TradeoffPoint& p : points)
            c.series.push_back({p.label, {p.ms}, {p.accuracy}, {}, false, es.style_of(p.label)});
        Series line{"Pareto front", {}, {}, {}, true, front_style};
        for (std::size_t i : front) line.x.push_back(points[i].ms), line.y.push_back(points[i].accuracy);
        c.series.push_back(line);
        c.reading = front_reading(sc, measure, points, front) +
                    " A configuration is on the front when no other is both faster and at least as "
                    "accurate; up and left is better." +
                    (all_one(!is_precision) ? std::string(" The ") + (is_precision ? "recall" : "precision") +
                                                  " of every configuration on " + sc + " is 1."
                                            : "");
        h.chart(c);
    }
}

/// Speed against accuracy: per scene, time per frame against precision and against recall of
/// every configuration (query levels included: candidates, boxes, shapes; accel/narrow/narrow_phase.h),
/// with the Pareto front named. A scene where every configuration is exact gets one line.
void accuracy_section(Html& h, const Entries& es) {
    h.heading("Speed against accuracy");
    std::vector<std::string> exact_scenes, unverified;
    for (const std::string& sc : es.scenes) {
        std::vector<const Entry*> here;
        bool all_exact = true;
        for (const Entry& e : es.all)
            if (e.scene == sc) {
                if (!e.verified) {
                    unverified.push_back(e.label + " on " + sc);
                    continue;
                }
                here.push_back(&e);
                all_exact = all_exact && e.exact();
            }
        if (here.empty()) continue;
        if (all_exact)
            exact_scenes.push_back(sc);
        else
            tradeoff_charts(h, es, sc, here);
    }
    if (!exact_scenes.empty())
        h.paragraph((exact_scenes.size() == es.scenes.size()
                         ? "Every configuration was exact on every scene ("
                         : "Every configuration was exact on " + join(exact_scenes, ", ") + " (") +
                    std::string("no mismatches, precision = recall = 1 against the shapes), so speed is the only "
                                "difference there."));
    if (!unverified.empty())
        h.paragraph("Not verified against the ground truth (accuracy unknown, left out of the charts): " +
                    join(unverified, ", ") + ".");
    std::vector<std::vector<std::string>> rows;
    for (const Entry& e : es.all)
        rows.push_back({e.scene, e.label, fixed(e.hits, 0), fixed(e.missed, 0), fixed(e.extra, 0),
                        fixed(e.duplicate, 0), e.verified ? fixed(e.precision(), 3) : "-",
                        e.verified ? fixed(e.recall(), 3) : "-"});
    h.table({"scene", "configuration", "hits", "missed", "extra", "duplicate", "precision", "recall"}, rows,
            "Hit sets against the ground truth: mismatches against each configuration's own contract (all "
            "frames), precision and recall against the shapes (measured frames)");
}

/// A model's (measured, predicted) cost per ray, medians per configuration, in configuration order.
std::vector<std::pair<double, double>> predicted_points(const CandidateModel& model) {
    std::map<int, std::pair<std::vector<double>, std::vector<double>>> per_config;
    for (std::size_t i = 0; i < model.problem.y.size(); ++i) {
        per_config[model.problem.group[i]].first.push_back(model.problem.y[i]);
        per_config[model.problem.group[i]].second.push_back(model.fit.predict(model.problem.x[i]));
    }
    std::vector<std::pair<double, double>> out;
    for (auto& [g, v] : per_config) out.emplace_back(spread_of(v.first).median, spread_of(v.second).median);
    return out;
}

/// Predicted against measured ray-cast cost per ray, one series per structure's chosen model.
void predicted_chart(Html& h, const std::vector<StructureModels>& models, const NoiseFloor& noise) {
    Chart c;
    c.title = "Predicted against measured ray-cast cost per ray";
    c.x_label = "measured (ns per ray)";
    c.y_label = "predicted by the chosen model (ns per ray)";
    c.log_x = c.log_y = true;
    c.extra = "set style line 99 lc rgb '#888888' dt 2\n";
    double lo = INFINITY, hi = 0;
    std::string errors;
    for (const StructureModels& m : models) {
        const CandidateModel* chosen = m.chosen("raycast");
        if (!chosen) continue;
        Series s{m.structure + " (" + chosen->name + ")", {}, {}, {}, false};
        for (const auto& [measured, predicted] : predicted_points(*chosen)) {
            s.x.push_back(measured);
            s.y.push_back(predicted);
            lo = std::min(lo, measured), hi = std::max(hi, measured);
        }
        c.series.push_back(s);
        const StructureNoise* n = noise.find(m.structure);
        errors += (errors.empty() ? "" : ", ") + m.structure + " " + fixed(100 * chosen->heldout_error, 1) + "%" +
                  (n && std::isfinite(n->raycast) ? " (repeats " + noise_text(n->raycast, n->raycast_p90) + ")" : "");
    }
    if (hi > 0) {
        std::ostringstream ref;  // y = x solid, and the ±10% band dashed
        for (const double band : {1.0, 1.1, 0.9})
            ref << "set arrow from " << lo * 0.7 << "," << lo * 0.7 * band << " to " << hi * 1.4 << ","
                << hi * 1.4 * band << " nohead " << (band == 1 ? "lc rgb '#444444'" : "dt 2 lc rgb '#999999'") << "\n";
        c.extra += ref.str();
    }
    c.reading =
        "One point per configuration (median over its frames); the solid line is a perfect prediction, the dashed "
        "band ±10%. "
        "Held-out error (configurations left out of the fit), with the scatter of repeated measurements of the "
        "same cell in parentheses: " +
        errors + ".";
    h.chart(c);
}

/// The noise floor beside the model's error: what the machine cannot repeat, no model can predict.
void noise_section(Html& h, const std::vector<StructureModels>& models, const NoiseFloor& noise,
                   const std::vector<SlowCell>& slow_cells) {
    std::vector<std::vector<std::string>> floor;
    for (const StructureModels& m : models) {
        const CandidateModel* chosen = m.chosen("raycast");
        const StructureNoise* n = noise.find(m.structure);
        floor.push_back({m.structure, chosen ? fixed(100 * chosen->heldout_error, 1) + "%" : "-",
                         n ? noise_text(n->raycast, n->raycast_p90) : "-",
                         n ? noise_text(n->update, n->update_p90) : "-",
                         n ? std::to_string(n->cells) + " (" + std::to_string(n->repetitions) + ")" : "0",
                         n ? std::to_string(n->slow) : "0"});
    }
    h.table({"structure", "held-out error (ray cast)", "repeatability (ray cast)", "repeatability (update)",
             "repeated cells (repetitions)", "slow repetitions"},
            floor,
            "Noise floor: how far the first two repetitions of a cell differ in time per frame, (max - min) / "
            "median, median / 90th percentile over the repeated cells (needs repetitions >= 2); error above it is "
            "the model's");
    std::string state = std::to_string(noise.with_state) + " of " + std::to_string(noise.cells) +
                        " cells have the machine's state recorded";
    if (noise.with_state)
        state += " (median 1-minute load " + fixed(noise.load_median, 2) + ", median calibration loop " +
                 fixed(noise.calibration_median_ns / 1e6, 3) + " ms); " + std::to_string(noise.slow) +
                 " were measured while the calibration loop or memory probe ran more than 10% above its run's median";
    h.paragraph(state + ".");
    // The slow cells are marked "*" in Table 6.2 (a list here would repeat every scene's name).
    if (noise.slow) {
        double worst = 0;
        for (const SlowCell& sc : slow_cells) worst = std::max(worst, sc.calibration_ratio);
        h.paragraph("Cells measured on a slow machine are marked * in Table 6.2; the slowest calibration loop ran " +
                    fixed(100 * (worst - 1), 0) + "% above its run's median.");
    }
}

/// Thesis Table 6.3's analog and the model selection of each structure.
void breakdown_tables(Html& h, const std::vector<StructureModels>& models,
                      const std::vector<CostBreakdown>& breakdown) {
    std::vector<std::vector<std::string>> rows;
    const BreakdownColumns columns = breakdown_columns(breakdown, "×");
    for (std::size_t i = 0; i < breakdown.size(); ++i) {
        rows.push_back({breakdown[i].scene, config_label(breakdown[i].structure, breakdown[i].params)});
        rows.back().insert(rows.back().end(), columns.rows[i].begin(), columns.rows[i].end());
    }
    std::vector<std::string> header{"scene", "configuration"};
    header.insert(header.end(), columns.header.begin(), columns.header.end());
    h.table(header, rows,
            "Thesis Table 6.3 analog: ns per ray; counts per ray; C terms from each structure's chosen model");
    std::vector<std::vector<std::string>> sel;
    for (const StructureModels& m : models)
        for (const CandidateModel& cm : m.raycast) {
            std::string coefficients;
            for (const Coefficient& co : cm.fit.coefficients)
                coefficients +=
                    (coefficients.empty() ? "" : "; ") + co.name + " " + fixed(co.value, 3) +
                    (std::isfinite(co.ci_low) ? " [" + fixed(co.ci_low, 3) + ", " + fixed(co.ci_high, 3) + "]" : "") +
                    (co.spans_zero ? " ~0?" : "");
            sel.push_back({m.structure, cm.name, fixed(100 * cm.heldout_error, 1) + "%", fixed(cm.fit.r2, 3),
                           cm.fit.status(), cm.chosen ? "chosen" : "",
                           cm.fit.status() == "ok" ? coefficients : "(not identifiable)"});
        }
    h.table({"structure", "model", "held-out error", "R²", "status", "", "coefficients (ns, 95% interval)"}, sel,
            "Model selection: the smallest model within max(0.5 points, 5%) of the best held-out error is chosen");
}

/// Which terms each structure's chosen model kept, against the calibration, and how well it
/// predicts scenes it was not fitted on.
void chosen_terms(Html& h, const std::vector<StructureModels>& models) {
    std::vector<std::vector<std::string>> chosen_rows;
    int calibrated = 0, within = 0;
    for (const StructureModels& m : models) {
        const CandidateModel* cm = m.chosen("raycast");
        if (!cm) continue;
        std::string terms, against;
        for (const Coefficient& co : cm->fit.coefficients) {
            terms += (terms.empty() ? "" : ", ") + co.name + " " + fixed(co.value, 3);
            if (std::isfinite(co.prior)) {
                ++calibrated;
                within += !co.at_bound;
                against += (against.empty() ? "" : ", ") + co.name + " ×" + fixed(co.value / co.prior, 2) +
                           (co.at_bound ? " (at the 3× bound)" : "");
            }
        }
        chosen_rows.push_back({m.structure, cm->name, terms, against.empty() ? "no calibration value" : against,
                               cm->dropped.empty() ? "-" : join(cm->dropped, "; "),
                               std::isfinite(cm->heldout_error) ? fixed(100 * cm->heldout_error, 1) + "%" : "-",
                               std::isfinite(m.loso_error) ? fixed(100 * m.loso_error, 1) + "%" : "-"});
    }
    h.table({"structure", "chosen model", "terms (ns per unit; slow>L…: fraction)", "against calibration",
             "dropped, and why", "held-out (configurations)", "leave one scene out (time per frame)"},
            chosen_rows,
            "Chosen ray-cast terms per structure. Calibration: each structure on fixed micro-scenes that vary "
            "N_RB and N_T independently; its pinned values are priors bounding the fit to 3×. Leave one scene "
            "out: each scene's time per frame (update + rays × C) predicted from a fit on the other scenes.");
    if (calibrated)
        h.paragraph(
            std::to_string(within) + " of " + std::to_string(calibrated) +
            " calibrated coefficients of the chosen models lie inside the 3× range of their calibration "
            "value without touching its bound" +
            (within == calibrated ? "." : "; the others are held at the bound: the run's frames pull them further."));
    else
        h.paragraph(
            "The run has no calibration (it was made before runs stored one): the coefficients are fitted "
            "without priors and collinear counters may not be told apart.");
}

/// Cost model (thesis eq. 5.4, Table 6.3): predicted against measured, the noise floor, the
/// breakdown, model selection and the chosen terms.
void cost_model_section(Html& h, const ReportData& d, const std::vector<StructureModels>& models,
                        const std::vector<CostBreakdown>& breakdown) {
    h.heading("Cost model (thesis eq. 5.4, Table 6.3)");
    predicted_chart(h, models, d.noise);
    noise_section(h, models, d.noise, d.slow);
    breakdown_tables(h, models, breakdown);
    chosen_terms(h, models);
}

/// Thesis Table 6.4: DBVH incremental against full SAH, where the run has both.
void dbvh_section(Html& h, const std::vector<CostBreakdown>& breakdown) {
    std::vector<std::vector<std::string>> rows;
    for (const CostBreakdown& b : breakdown)
        if (b.structure == "dbvh")
            rows.push_back({b.scene, config_label(b.structure, b.params), fixed(b.c_total, 1), fixed(b.n_tp, 1),
                            fixed(b.n_fp, 1), fixed(b.n_t, 1)});
    if (rows.size() > 1) {
        h.heading("Tree quality of the dynamic BVH (thesis Table 6.4)");
        h.table({"scene", "configuration", "C_total (ns/ray)", "N_TP", "N_FP", "N_T"}, rows,
                "DBVH incremental insertion against full binned-SAH rebuilds");
    }
}

/// Per-frame series on the largest scene: ray cast, and the trees' SAH cost.
void over_time_section(Html& h, const Entries& es) {
    h.heading("Over time, on " + es.largest);
    Chart c;
    c.title = "Ray cast per frame on " + es.largest;
    c.x_label = "frame";
    c.y_label = "ray cast per frame (ms)";
    c.log_y = true;
    for (const Entry& e : es.all) {
        if (e.scene != es.largest || e.frame_raycast_ms.empty()) continue;
        Series s{e.label, {}, {}, {}, true, es.style_of(e.label)};
        for (std::size_t f = 0; f < e.frame_raycast_ms.size(); ++f)
            s.x.push_back(double(f + 1)), s.y.push_back(e.frame_raycast_ms[f]);
        c.series.push_back(s);
    }
    const auto [worst, worst_drift] = largest_drift(es);
    c.reading = worst.empty()
                    ? "No configuration changed by more than noise from the first to the last quarter of the frames."
                    : "Largest change from the first to the last quarter of the frames: " + worst + ", " +
                          fixed(100 * worst_drift, 1) + "% (noise included).";
    h.chart(c);

    Chart sah;
    sah.title = "SAH cost of the tree per frame on " + es.largest + " (eq. 3.2)";
    sah.x_label = "frame";
    sah.y_label = "SAH cost (relative to the root's area)";
    std::string growth, grew, fell;
    for (const SahChange& t : sah_changes(es)) {
        growth += (growth.empty() ? "" : ", ") + t.label + " " + fixed(100 * t.change, 1) + "%";
        // Beyond 2% the tree's quality moved; within it, the tree kept its quality.
        if (t.change > 0.02) grew += (grew.empty() ? "" : ", ") + t.label;
        if (t.change < -0.02) fell += (fell.empty() ? "" : ", ") + t.label;
        sah.series.push_back(t.series);
    }
    if (sah.series.empty()) return;
    sah.reading = "Change of the SAH cost from the first to the last frame: " + growth + ". " +
                  (grew.empty() ? std::string("No tree's cost grew by more than 2%")
                                : "The cost grew by more than 2% for " + grew) +
                  (fell.empty() ? std::string(".") : "; it fell by more than 2% for " + fell + ".");
    h.chart(sah);
}

/// Memory against time per frame, for every configuration.
void memory_chart(Html& h, const Entries& es) {
    Chart c;
    c.title = "Memory against time per frame";
    c.x_label = "memory (bytes per object)";
    c.y_label = "update + ray cast per frame (ms)";
    c.log_x = c.log_y = true;
    const Entry* most = nullptr;
    for (const std::string& l : es.labels) {
        Series s{l, {}, {}, {}, false, es.style_of(l)};
        for (const Entry& e : es.all)
            if (e.label == l) {
                s.x.push_back(e.memory_per_object);
                s.y.push_back(e.total_ms());
                if (!most || e.memory_per_object > most->memory_per_object) most = &e;
            }
        c.series.push_back(s);
    }
    c.reading = most ? "Most memory per object: " + most->label + " on " + most->scene + ", " +
                           fixed(most->memory_per_object, 0) + " bytes per object."
                     : "No data.";
    h.chart(c);
}

/// Build time against object count, with each configuration's log-log slope.
void build_chart(Html& h, const Entries& es) {
    Chart b;
    b.title = "Build time against object count";
    b.x_label = "objects";
    b.y_label = "build (ms)";
    b.log_x = b.log_y = true;
    std::string slopes;
    for (const std::string& l : es.labels) {
        Series s{l, {}, {}, {}, true, es.style_of(l)};
        std::vector<std::pair<double, double>> points;
        for (const Entry& e : es.all)
            if (e.label == l) points.emplace_back(e.objects, e.build_ms);
        std::sort(points.begin(), points.end());
        for (auto [x, y] : points) s.x.push_back(x), s.y.push_back(y);
        const double slope = log_log_slope(s.x, s.y);
        if (std::isfinite(slope)) {
            s.name += " (slope " + fixed(slope, 2) + ")";
            slopes += (slopes.empty() ? "" : ", ") + l + " " + fixed(slope, 2);
        }
        b.series.push_back(s);
    }
    b.reading = slopes.empty() ? "Too few object counts to fit slopes."
                               : "Slopes of log build time against log object count (1 = linear): " + slopes + ".";
    h.chart(b);
}

/// Memory against time; build time against object count; growth with the object count on the
/// category with the most distinct object counts (experiments/scale.json: irregular scenes of 10^4
/// to 10^6 objects).
void memory_build_section(Html& h, const Entries& es) {
    h.heading("Memory and build");
    memory_chart(h, es);
    build_chart(h, es);
    const std::string category = growth_category(es.all);
    if (category.empty()) return;
    std::vector<GrowthPoint> points;
    for (const Entry& e : es.all)
        if (e.category == category) points.push_back({e.label, e.objects, e.total_ms(), es.style_of(e.label)});
    h.heading("Growth with the object count");
    h.chart(growth_chart(points, category + " scenes"));
}

/// Failure-mode scenes (by their generator) against brute force and against a benign scene of
/// the same size, for every configuration.
void failure_section(Html& h, const Entries& es) {
    const std::vector<std::string> failure_generators = failure_mode_generators();
    std::vector<std::string> failure_scenes;
    for (const std::string& sc : es.scenes)
        if (std::any_of(es.all.begin(), es.all.end(), [&](const Entry& e) {
                return e.scene == sc && std::count(failure_generators.begin(), failure_generators.end(), e.category);
            }))
            failure_scenes.push_back(sc);
    if (failure_scenes.empty()) return;
    h.heading("Where methods fail");
    auto ratio = [](double r) { return std::isnan(r) ? std::string("-") : fixed(r, r < 10 ? 2 : 1); };
    std::vector<std::string> header{"configuration"};
    header.insert(header.end(), failure_scenes.begin(), failure_scenes.end());
    std::vector<std::vector<std::string>> rows;
    std::size_t wrong = 0;
    for (const std::string& l : es.labels) {
        std::vector<std::string> row{l};
        bool any = false;
        for (const std::string& sc : failure_scenes) {
            const Entry* e = es.find(sc, l);
            if (!e) {
                row.push_back("-");
                continue;
            }
            any = true;
            const FailureCell f = failure_cell(es.all, *e);
            if (f.mismatches > 0) ++wrong;
            row.push_back((f.mismatches > 0 ? "WRONG (" + fixed(f.mismatches, 0) + ")" : std::string("ok")) + "; " +
                          ratio(f.vs_bf) + " bf; " + ratio(f.vs_benign) + " benign");
        }
        if (any) rows.push_back(row);
    }
    h.paragraph(
        "Scenes built to break an assumption: stadium (one huge box around a tiny dense "
        "cluster), identical (stacks of equal boxes), same-centroid (stacks with one centroid), flat "
        "(zero-thickness boxes in one plane), slivers (long thin and zero-volume boxes), outlier (one "
        "box 10^6 scene sizes away). Each cell: ok or WRONG (mismatches against the ground truth); "
        "cost (update + ray cast per frame, medians) divided by brute force's on the same scene; and "
        "divided by the same configuration's cost on the benign scene of the same size (generated "
        "irregular, else uniform, with as many objects; '-' when the run has none). " +
        std::string(wrong == 0 ? "Every configuration was exact on every failure scene."
                               : std::to_string(wrong) + " configuration-scene pairs were not exact."));
    h.table(header, rows, "Where methods fail: correctness, cost / brute force, cost / benign scene of the same size");
}

/// The thesis' conclusions against this run (analysis/findings.h; `rcbench findings` writes the same).
void findings_section(Html& h, const std::vector<Finding>& findings) {
    h.heading("Findings: the thesis' conclusions against this run");
    for (const Finding& f : findings) {
        h.paragraph(f.claim + " (thesis " + f.source + "): " + verdict_name(f.verdict) + ". " + f.summary);
        if (f.evidence.empty()) continue;
        std::vector<std::vector<std::string>> rows;
        for (const std::string& e : f.evidence) rows.push_back({e});
        h.table({"evidence"}, rows, f.claim);
    }
}

/// The History section: per-run medians of the experiment's runs up to this one, on the largest
/// scene, one line per configuration; the reading lists the steps of every scene and configuration
/// (ray cast and update), found as runner/history.h describes. Nothing when this is the first run.
void history_section(Html& h, const History& history, const std::string& experiment, const Entries& es) {
    const std::vector<HistorySeries>& cast = history.cast;
    const std::vector<HistorySeries>& update = history.update;
    const HistoryQuery& q = history.query;
    const std::string& largest = es.largest;
    // The runs in run order (each series lists its points in that order).
    std::vector<std::tuple<std::string, std::int64_t, std::string>> runs;  // (started_at, id, commit)
    for (const HistorySeries& s : cast)
        for (const HistoryPoint& p : s.points) runs.emplace_back(p.started_at, p.run, p.commit);
    std::sort(runs.begin(), runs.end());
    runs.erase(std::unique(runs.begin(), runs.end(),
                           [](const auto& a, const auto& b) { return std::get<1>(a) == std::get<1>(b); }),
               runs.end());
    if (runs.size() < 2) return;
    auto position = [&](std::int64_t id) {
        const auto at = std::find_if(runs.begin(), runs.end(), [&](const auto& r) { return std::get<1>(r) == id; });
        return at == runs.end() ? std::nan("") : double(at - runs.begin() + 1);
    };
    h.heading("History");
    Chart c;
    c.title = "Ray cast per frame over the runs of " + experiment + ", on " + largest;
    c.x_label = "run (commit)";
    c.y_label = "ray cast per frame (ms, median)";
    c.log_y = true;
    // Tics name the run and its commit (text from the database: only plain characters reach gnuplot,
    // printed as written).
    std::string tics;
    const std::size_t every = (runs.size() + 11) / 12;
    for (std::size_t i = 0; i < runs.size(); i += every) {
        std::string label = std::to_string(std::get<1>(runs[i])) + " " + short_commit(std::get<2>(runs[i]));
        label.erase(std::remove_if(label.begin(), label.end(),
                                   [](unsigned char ch) { return !(std::isalnum(ch) || std::strchr(" .-_+", ch)); }),
                    label.end());
        tics += (tics.empty() ? "" : ", ") + ("'" + label + "' " + std::to_string(i + 1));
    }
    c.extra = "set xtics (" + tics +
              ") rotate by -30 font 'sans,9' noenhanced\nset xrange [0.5:" + std::to_string(runs.size()) + ".5]\n";
    for (const HistorySeries& s : cast) {
        if (s.scene != largest) continue;
        const std::string label = config_label(s.structure, s.params);
        Series line{label, {}, {}, {}, true, es.style_of(label)};
        for (const HistoryPoint& p : s.points)
            line.x.push_back(position(p.run)), line.y.push_back(p.median_ns / 1e6), line.labels.emplace_back();
        for (const Step& step : s.steps)  // the steps written at the run where the new level starts
            line.labels[step.at] = (step.change >= 0 ? "+" : "") + fixed(100 * step.change, 0) + "%";
        c.series.push_back(line);
    }
    std::vector<std::string> found;
    std::size_t series = 0;
    for (const auto* metric : {&cast, &update})
        for (const HistorySeries& s : *metric) {
            ++series;
            for (const Step& step : s.steps) {
                const HistoryPoint& p = s.points[step.at];
                found.push_back(config_label(s.structure, s.params) + " on " + s.scene + ", " +
                                (metric == &cast ? "ray cast " : "update ") + (step.change >= 0 ? "+" : "") +
                                fixed(100 * step.change, 1) + "% at run " + std::to_string(p.run) + " (" +
                                short_commit(p.commit) + ")");
            }
        }
    const std::string method = " A step is a change of level between up to " + std::to_string(q.steps.window) +
                               " runs before and after it beyond " + fixed(q.steps.k, 0) +
                               " MADs of the frame times, with a Mann-Whitney U test p < " + fixed(q.steps.alpha, 2) +
                               ".";
    if (found.empty()) {
        c.reading = "No step beyond the runs' noise in any of the " + std::to_string(series) +
                    " series (scene × configuration, ray cast and update) over the " + std::to_string(runs.size()) +
                    " runs up to this one." + method;
    } else {
        const std::size_t shown = std::min<std::size_t>(found.size(), 6);
        c.reading = std::to_string(found.size()) + " step" + (found.size() > 1 ? "s" : "") +
                    " beyond the runs' noise in " + std::to_string(series) + " series over the " +
                    std::to_string(runs.size()) + " runs up to this one: " +
                    join(std::vector<std::string>(found.begin(), found.begin() + std::ptrdiff_t(shown)), "; ") +
                    (found.size() > shown
                         ? "; and " + std::to_string(found.size() - shown) + " more (rcbench history lists them)"
                         : "") +
                    "." + method;
    }
    h.chart(c);
}

/// The page around the sections: one self-contained file, no scripts, no remote resources.
std::string page(const std::string& experiment, const Html& h) {
    std::ostringstream page;
    page << "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8><title>rcbench report: "
         << html_escape(experiment)
         << "</title>\n<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}"
            "table{border-collapse:collapse;margin:1em "
            "0;font-size:13px}caption{text-align:left;font-weight:bold;padding:4px 0}"
            "th,td{border:1px solid #ccc;padding:3px 7px}td.n{text-align:right;font-variant-numeric:tabular-nums}"
            "th{background:#f2f2f2}figure.chart{margin:1.5em 0}figcaption{font-size:14px;color:#333;max-width:820px}"
            "h2{border-bottom:1px solid #ddd;padding-bottom:4px;margin-top:2em}</style></head>\n<body>\n<h1>rcbench "
            "report: "
         << html_escape(experiment) << "</h1>\n"
         << h.str() << "</body></html>\n";
    return page.str();
}

}  // namespace

ReportSummary write_report(Database& db, std::int64_t run, const std::string& path) {
    const ReportData d = load_report_data(db, run);
    const Entries es(d.entries);
    const std::vector<StructureModels> models = fit_cost_models(d.frames, d.model_inputs);
    const std::vector<CostBreakdown> breakdown = cost_breakdown(d.frames, models);

    Html h;
    h.paragraph("Experiment " + d.head.experiment + ", run " + std::to_string(run) + " started " + d.head.started +
                " from commit " + d.head.commit + " by " + d.head.binary + " on " + d.head.cpu +
                ". Times are medians over frames (and over repetitions); a frame casts its rays as one batch (one per "
                "query kind when it asks for several).");
    tables_section(h, es, d.slow);
    motion_lines(h, d.motion);
    update_raycast_section(h, es);
    accuracy_section(h, es);
    cost_model_section(h, d, models, breakdown);
    if (!d.kind_frames.empty()) query_kinds_section(h, kind_cells(models, d.kind_frames));
    peer_sections(h, es);
    dbvh_section(h, breakdown);
    over_time_section(h, es);
    memory_build_section(h, es);
    failure_section(h, es);
    findings_section(h, d.findings);
    history_section(h, d.history, d.head.experiment, es);
    write_file_atomically(path, page(d.head.experiment, h));
    return {run, h.charts(), h.tables()};
}

}  // namespace rcb
