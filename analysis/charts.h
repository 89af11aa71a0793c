#pragma once
/// Charts drawn by gnuplot (Debian's gnuplot-nox) as SVG, for embedding in the HTML report.
/// rcbench writes the data and a gnuplot script to a temporary folder and runs gnuplot on it;
/// no chart is drawn by hand.

#include <string>
#include <vector>

namespace rcb {

/// One named series of (x, y) points, drawn with points and optionally lines.
struct Series {
    std::string name;
    std::vector<double> x, y;
    std::vector<std::string> labels;  ///< optional text at each point
    bool lines = false;
    int style = 0;  ///< colour and marker; 0: by position. Give a series the same style in every chart.
};

struct Chart {
    std::string title;
    std::string x_label, y_label;  ///< with units, e.g. "update per frame (ms)"
    bool log_x = false, log_y = false;
    std::vector<Series> series;
    std::string extra;    ///< extra gnuplot commands (e.g. a y = x reference line)
    std::string reading;  ///< one sentence saying what the chart shows
};

/// One configuration's cost and accuracy on a scene, for the speed-against-accuracy charts.
struct TradeoffPoint {
    std::string label;
    double ms = 0;        ///< time per frame (update + rays, narrow phase included)
    double accuracy = 1;  ///< precision or recall, 0..1
};

/// The Pareto front of `points` (the fastest configuration for each accuracy level): indices of
/// the points that no other point beats by being faster and at least as accurate, fastest first.
/// Of equal points the first is kept. Non-finite points are never on it.
std::vector<std::size_t> pareto_front(const std::vector<TradeoffPoint>& points);

/// "On S, the precision front is: a (0.400 ms, precision 0.31), b (0.600 ms, 0.78)." from the data.
std::string front_reading(const std::string& scene, const std::string& measure,
                          const std::vector<TradeoffPoint>& points, const std::vector<std::size_t>& front);

/// Least-squares slope of log(y) against log(x) over the points with x, y > 0; NaN with fewer than
/// two distinct x.
double log_log_slope(const std::vector<double>& x, const std::vector<double>& y);

/// One configuration's per-frame cost (update + ray cast, ms) at one object count.
struct GrowthPoint {
    std::string label;
    double objects = 0;
    double frame_ms = 0;
    int style = 0;  ///< as Series::style
};

/// Per-frame cost against object count on log-log axes: a series per label (in order of first
/// appearance), its least-squares slope in the legend, and a reading computed from the points: the
/// slopes, the flattest and steepest growth, and the fastest and slowest at the largest count.
/// `scenes` names what the points come from ("irregular scenes").
Chart growth_chart(const std::vector<GrowthPoint>& points, const std::string& scenes);

/// The chart as an SVG document. Throws std::runtime_error when gnuplot is missing or fails.
std::string render_svg(const Chart& chart);

/// True when a gnuplot executable is on the PATH.
bool gnuplot_available();

}  // namespace rcb
