// The HTML report: every chart drawn (gnuplot), every section present, and the page rendered by
// headless Chromium with every chart in the DOM and a screenshot that is not blank.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "analysis/charts.h"
#include "analysis/report.h"
#include "accel/registry.h"
#include "runner/experiment.h"
#include "runner/run_experiment.h"
#include "runner/store.h"
#include "tests/real_data.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

std::size_t count_of(const std::string& text, const std::string& needle) {
    std::size_t n = 0;
    for (auto pos = text.find(needle); pos != std::string::npos; pos = text.find(needle, pos + 1)) ++n;
    return n;
}

std::string read(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

/// Runs a small experiment through the library into `db_path`; returns the run id.
std::int64_t small_run(const std::string& db_path) {
    const Experiment e = parse_experiment(
        R"({"name": "report-test", "frames": 4, "rays_per_frame": 200,
            "scenes": [{"generator": "uniform", "objects": 1500}, {"generator": "irregular", "name": "irregular-dense", "objects": 3000, "ray_mix": "dense,center"},
                       {"generator": "irregular", "objects": 6000}],
            "structures": [{"name": "bf"}, {"name": "dbvh", "grids": [{"mode": "incremental"}, {"mode": "rebuild"}]}, {"name": "lbvh"}]})",
        "report-test.json", ".");
    RunOptions options;
    options.db = db_path;
    options.new_run = true;
    return run_experiment(e, "report-test.json", options).run;
}

TEST(Report, DrawsEveryChartAndRendersInChromium) {
    ASSERT_TRUE(gnuplot_available())
        << "gnuplot is part of rcbench's dependencies (scripts/setup.sh installs gnuplot-nox)";
    const test::TempDir temp("report", "charts");
    const fs::path& dir = temp.path();
    const std::string db_path = (dir / "r.db").string();
    const std::int64_t run = small_run(db_path);

    Database db(db_path, true);
    const fs::path html = dir / "report.html";
    const ReportSummary s = write_report(db, run, html.string());
    const std::string page = read(html);
    // Two scene categories (two update/ray-cast charts), predicted/measured, per-frame series, SAH
    // cost (dbvh and lbvh report it), memory, build, growth (irregular at two counts); every configuration is exact at
    // the box level on box scenes, so speed against accuracy is one line, not a flat chart.
    EXPECT_EQ(s.charts, 8u);
    EXPECT_NE(page.find("Every configuration was exact on every scene (no mismatches, precision = recall = 1"),
              std::string::npos);
    EXPECT_EQ(count_of(page, "<svg"), s.charts);
    EXPECT_EQ(count_of(page, "<figcaption>"), s.charts);  // every chart has its sentence
    EXPECT_EQ(count_of(page, "<img"), 0u);                // nothing that could be a broken image
    for (const char* section : {"Table 6.1", "Table 6.2", "Table 6.3", "Table 6.4", "Speed against accuracy",
                                "Build time against object count", "Per-frame cost against object count"})
        EXPECT_NE(page.find(section), std::string::npos) << section;
    EXPECT_EQ(page.find("http://www.w3.org/1999/xlink\" href=\"http"), std::string::npos);  // no remote resources

    RCB_REQUIRE_REAL_DATA(fs::exists("/usr/bin/chromium"),
                          "Debian's chromium is not installed (scripts/setup.sh --test-tools installs it)");
    const std::string flags =
        "--headless --no-sandbox --disable-gpu --disable-quic --no-first-run --disable-background-networking "
        "--disable-component-update --disable-sync --user-data-dir=" +
        (dir / "profile").string();
    const fs::path shot = dir / "shot.png", dom = dir / "dom.html";
    const std::string url = "file://" + html.string();
    ASSERT_EQ(std::system(("timeout 120 chromium " + flags + " --window-size=1200,4000 --screenshot=" + shot.string() +
                           " " + url + " >/dev/null 2>&1")
                              .c_str()),
              0);
    ASSERT_EQ(
        std::system(
            ("timeout 120 chromium " + flags + " --dump-dom " + url + " > " + dom.string() + " 2>/dev/null").c_str()),
        0);
    // The rendered DOM holds every chart as parsed SVG with its plotted content.
    const std::string rendered = read(dom);
    EXPECT_EQ(count_of(rendered, "<svg"), s.charts);
    EXPECT_GE(count_of(rendered, "<path"), s.charts);
    // A blank or failed page compresses to a few kilobytes; charts and tables do not.
    const std::string png = read(shot);
    ASSERT_GT(png.size(), 8u);
    EXPECT_EQ(png.substr(1, 3), "PNG");
    EXPECT_GT(png.size(), 60'000u);
}

TEST(Report, SpeedAgainstAccuracyNamesEachScenesParetoFrontFromTheData) {
    ASSERT_TRUE(gnuplot_available());
    const test::TempDir temp("report", "front");
    const fs::path& dir = temp.path();
    const std::string db_path = (dir / "r.db").string();
    // The candidate level reports every object of the cells a ray crosses: recall 1, precision
    // below 1; the box level is exact on box scenes.
    const Experiment e = parse_experiment(
        R"({"name": "front-test", "frames": 3, "rays_per_frame": 200,
            "scenes": [{"generator": "uniform", "objects": 1500}],
            "structures": [{"name": "ug", "grids": [{"query": "candidates"}, {"query": "boxes"}]}, {"name": "bf"}]})",
        "front-test.json", ".");
    RunOptions options;
    options.db = db_path;
    options.new_run = true;
    const std::int64_t run = run_experiment(e, "front-test.json", options).run;
    Database db(db_path, true);
    const fs::path html = dir / "report.html";
    const ReportSummary s = write_report(db, run, html.string());
    const std::string page = read(html);
    // One update/ray-cast chart, predicted/measured, per-frame series, memory, build (no BVH: no SAH
    // chart), and precision on the scene; recall is 1 everywhere, said in a line, not drawn flat.
    EXPECT_EQ(s.charts, 6u);
    EXPECT_NE(page.find("The recall of every configuration on uniform is 1."), std::string::npos);
    // The front in the reading, recomputed here from the stored cells.
    std::vector<TradeoffPoint> points;
    Statement q = db.prepare(
        "SELECT config.structure, config.params, cell.update_ns_median / 1e6 + cell.raycast_ns_median / 1e6, "
        "(SELECT 1.0 * sum(correct) / max(sum(returned), 1) FROM frame WHERE cell_id = cell.id AND warmup = 0) "
        "FROM cell JOIN config ON config.id = cell.config_id");
    double candidates_precision = 1;
    while (q.step()) {
        const bool candidates = q.text(1).find("candidates") != std::string::npos;
        if (candidates) candidates_precision = q.real(3);
        points.push_back({q.text(0) + (candidates ? " query=candidates" : ""), q.real(2), q.real(3)});
    }
    EXPECT_LT(candidates_precision, 1.0);
    ASSERT_EQ(points.size(), 3u);
    const std::vector<std::size_t> front = pareto_front(points);
    const std::size_t at = page.find("the precision front is: ");
    ASSERT_NE(at, std::string::npos);
    const std::string sentence = page.substr(at, page.find("</figcaption>", at) - at);
    // Every configuration of the front in order, and none other.
    std::size_t from = 0;
    for (std::size_t i : front) {
        const std::size_t found = sentence.find(points[i].label + " (", from);
        EXPECT_NE(found, std::string::npos) << points[i].label << " in " << sentence;
        from = found == std::string::npos ? from : found + 1;
    }
    for (std::size_t i = 0; i < points.size(); ++i)
        if (std::find(front.begin(), front.end(), i) == front.end()) {
            EXPECT_EQ(sentence.find(points[i].label + " ("), std::string::npos) << points[i].label;
        }
    EXPECT_EQ(points[front.back()].accuracy, 1.0);  // an exact configuration ends the front
    EXPECT_EQ(page.find("the recall front is: "), std::string::npos);
}

TEST(Report, GrowthChartFitsSlopesAndReadsThemFromTheData) {
    // a: costs 1, 10, 1000 ms at 10^4, 10^5, 10^6 (log10: 0, 1, 3 over 4, 5, 6: slope 1.5);
    // b: 0.05·sqrt(N) (slope 0.5); c: one count only (no slope).
    std::vector<GrowthPoint> points = {{"a", 1e4, 1.0}, {"a", 1e5, 10.0}, {"a", 1e6, 1000.0}, {"c", 1e5, 3.0}};
    for (double n : {1e6, 1e4, 1e5}) points.push_back({"b", n, 0.05 * std::sqrt(n)});
    const Chart c = growth_chart(points, "irregular scenes");
    EXPECT_TRUE(c.log_x && c.log_y);
    ASSERT_EQ(c.series.size(), 3u);
    EXPECT_EQ(c.series[0].name, "a (slope 1.50)");
    EXPECT_EQ(c.series[1].name, "c");
    EXPECT_EQ(c.series[2].name, "b (slope 0.50)");
    EXPECT_EQ(c.series[2].x, (std::vector<double>{1e4, 1e5, 1e6}));  // sorted by object count
    EXPECT_NE(c.reading.find("a 1.50, b 0.50"), std::string::npos) << c.reading;
    EXPECT_NE(c.reading.find("Flattest growth: b (0.50); steepest: a (1.50)"), std::string::npos) << c.reading;
    EXPECT_NE(c.reading.find("At 1000000 objects the fastest is b (50.000 ms per frame), the slowest a (1000.000 ms)"),
              std::string::npos)
        << c.reading;
    // One count per label: nothing to fit, and the reading says so.
    EXPECT_NE(growth_chart({{"a", 1e4, 1.0}, {"b", 1e4, 2.0}}, "x").reading.find("Too few object counts"),
              std::string::npos);
}

TEST(Report, ChartsPrintNamesAsWritten) {
    // gnuplot's enhanced text would set bullet_dbvt as "bullet" with a subscript "dbvt" (and drop
    // the underscore); legends, titles, axis labels and point labels print names as written.
    ASSERT_TRUE(gnuplot_available()) << "gnuplot is part of rcbench's dependencies";
    Chart c;
    c.title = "cost on irreg_l";
    c.x_label = "N_RB per ray";
    c.y_label = "C_T (ns)";
    c.series.push_back({"bullet_dbvt", {1, 2}, {1, 2}, {"uni_s", "x^2"}, true, 1});
    c.series.push_back({"lbvh query=candidates", {1, 2}, {2, 3}, {}, false, 2});
    const std::string svg = render_svg(c);
    for (const char* text : {"bullet_dbvt", "cost on irreg_l", "N_RB per ray", "C_T (ns)", "uni_s", "x^2"})
        EXPECT_NE(svg.find(std::string(">") + text + "<"), std::string::npos) << text;
    EXPECT_EQ(svg.find("bulletdbvt"), std::string::npos);  // the legend's <title> under enhanced text
}

TEST(Report, ChartsNeedGnuplotAndSayWhyWithout) {
    // render_svg names the missing tool instead of writing an empty chart.
    const char* path = std::getenv("PATH");
    const std::string saved = path ? path : "";
    setenv("PATH", "/nonexistent", 1);
    Chart c;
    c.title = "t";
    try {
        render_svg(c);
        setenv("PATH", saved.c_str(), 1);
        FAIL() << "rendered without gnuplot";
    } catch (const std::runtime_error& e) {
        setenv("PATH", saved.c_str(), 1);
        EXPECT_NE(std::string(e.what()).find("gnuplot not found"), std::string::npos);
    }
}

}  // namespace
}  // namespace rcb
