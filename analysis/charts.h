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

/// The chart as an SVG document. Throws std::runtime_error when gnuplot is missing or fails.
std::string render_svg(const Chart& chart);

/// True when a gnuplot executable is on the PATH.
bool gnuplot_available();

}  // namespace rcb
