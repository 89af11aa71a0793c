#include "analysis/charts.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "core/base/error.h"
#include "core/base/number_text.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

/// Text from the database (scene names, parameters) as gnuplot may print it: control bytes as
/// spaces, at most 120 characters (a 5 MB scene name made gnuplot run for minutes).
std::string printable(const std::string& s) {
    std::string out;
    for (char c : s.substr(0, 120)) out += (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) ? ' ' : c;
    return s.size() > 120 ? out + "..." : out;
}

/// A gnuplot string literal (single quotes; a quote is doubled).
std::string quoted(const std::string& s) {
    std::string q = "'";
    for (char c : printable(s)) q += c == '\'' ? std::string("''") : std::string(1, c);
    return q + "'";
}

/// Labels go into data files as one quoted token.
std::string data_label(const std::string& s) {
    std::string q = "\"";
    for (char c : printable(s)) q += c == '"' ? '\'' : c;
    return q + "\"";
}

/// A coordinate gnuplot can place: finite, and far from double's limits (gnuplot's own range
/// arithmetic overflows on values like 1e308 from a damaged database).
bool drawable(double v) { return std::isfinite(v) && std::abs(v) < 1e100; }

}  // namespace

std::vector<std::size_t> pareto_front(const std::vector<TradeoffPoint>& points) {
    std::vector<std::size_t> order;
    for (std::size_t i = 0; i < points.size(); ++i)
        if (std::isfinite(points[i].ms) && std::isfinite(points[i].accuracy)) order.push_back(i);
    // Fastest first, the more accurate first among equal times: then a point is on the front
    // exactly when it is more accurate than every point before it.
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
        if (points[a].ms != points[b].ms) return points[a].ms < points[b].ms;
        return points[a].accuracy > points[b].accuracy;
    });
    std::vector<std::size_t> front;
    for (std::size_t i : order)
        if (front.empty() || points[i].accuracy > points[front.back()].accuracy) front.push_back(i);
    return front;
}

std::string front_reading(const std::string& scene, const std::string& measure,
                          const std::vector<TradeoffPoint>& points, const std::vector<std::size_t>& front) {
    std::string out = "On " + scene + ", the " + measure + " front is: ";
    for (std::size_t k = 0; k < front.size(); ++k) {
        const TradeoffPoint& p = points[front[k]];
        out += (k ? ", " : "") + p.label + " (" + format_ms(p.ms) + " ms, " + (k ? "" : measure + " ") +
               fixed(p.accuracy, 2) + ")";
    }
    return out + ".";
}

bool gnuplot_available() { return std::system("command -v gnuplot >/dev/null 2>&1") == 0; }

std::string render_svg(const Chart& chart) {
    if (!gnuplot_available())
        throw std::runtime_error(
            "gnuplot not found: install Debian's gnuplot-nox (scripts/setup.sh does) to draw the report's charts");
    char pattern[] = "/tmp/rcbench-chart-XXXXXX";
    const char* dir_c = mkdtemp(pattern);
    if (!dir_c) throw std::runtime_error("cannot create a temporary folder for gnuplot");
    const fs::path dir(dir_c);
    // Names are printed as written: gnuplot's enhanced text (on by default for SVG) would set
    // bullet_dbvt as "bullet" with "dbvt" as a subscript. Tic labels keep it (10^4 on log axes).
    std::ostringstream script;
    script << "set terminal svg size 820,470 dynamic font 'sans,11' background rgb 'white'\n"
           << "set output " << quoted((dir / "chart.svg").string()) << "\n"
           << "set title " << quoted(chart.title) << " font 'sans,13' noenhanced\n"
           << "set xlabel " << quoted(chart.x_label) << " noenhanced\nset ylabel " << quoted(chart.y_label)
           << " noenhanced\n"
           << "set grid lc rgb '#dddddd'\nset key outside right top box opaque\nset border lc rgb '#555555'\n";
    if (chart.log_x) script << "set logscale x\n";
    if (chart.log_y) script << "set logscale y\n";
    script << chart.extra << "\n";
    std::string plot;
    int index = 0;
    for (const Series& s : chart.series) {
        if (s.x.empty()) continue;
        const fs::path data = dir / ("series" + std::to_string(index) + ".dat");
        std::ofstream out(data);
        out.precision(10);
        std::size_t points = 0;
        for (std::size_t i = 0; i < s.x.size(); ++i) {
            if (!drawable(s.x[i]) || !drawable(s.y[i])) continue;
            if ((chart.log_x && s.x[i] <= 0) || (chart.log_y && s.y[i] <= 0)) continue;  // not drawable on a log axis
            out << s.x[i] << ' ' << s.y[i] << ' ' << data_label(i < s.labels.size() ? s.labels[i] : "") << '\n';
            ++points;
        }
        if (points == 0) continue;  // gnuplot fails on a plot whose every file is empty
        const int style = (s.style > 0 ? s.style - 1 : index) % 8 + 1;
        plot += (plot.empty() ? "plot " : ", ") + quoted(data.string()) + " using 1:2 with " +
                (s.lines ? "linespoints" : "points") + " pt " + std::to_string(style % 7 + 5) + " ps 1.2 lw 1.5 lc " +
                std::to_string(style) + " title " + quoted(s.name) + " noenhanced";
        if (!s.labels.empty())
            plot += ", " + quoted(data.string()) +
                    " using 1:2:3 with labels offset 0.8,0.6 font 'sans,8' tc rgb '#444444' noenhanced notitle";
        ++index;
    }
    if (plot.empty()) {  // nothing drawable (a damaged database): an empty frame, not a gnuplot error
        script << "unset logscale\nset xrange [0:1]\nset yrange [0:1]\n";
        plot = "plot NaN notitle";
    }
    script << plot << "\n";
    {
        std::ofstream out(dir / "chart.gp");
        out << script.str();
    }
    const std::string command =
        "gnuplot " + quoted((dir / "chart.gp").string()) + " 2>" + quoted((dir / "err.txt").string());
    const int rc = std::system(command.c_str());
    const auto read = [&](const char* name) {
        std::ostringstream text;
        text << std::ifstream(dir / name).rdbuf();
        return text.str();
    };
    const std::string svg = read("chart.svg"), err = read("err.txt");
    std::error_code ec;
    fs::remove_all(dir, ec);
    if (rc != 0 || svg.find("<svg") == std::string::npos)
        throw std::runtime_error("gnuplot failed to draw '" + chart.title + "': " + err.substr(0, 300));
    // Drop the XML prolog and doctype so the SVG can sit inline in HTML.
    return svg.substr(svg.find("<svg"));
}

double log_log_slope(const std::vector<double>& x, const std::vector<double>& y) {
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    int n = 0;
    for (std::size_t i = 0; i < x.size() && i < y.size(); ++i) {
        if (!(x[i] > 0 && y[i] > 0 && std::isfinite(x[i]) && std::isfinite(y[i]))) continue;
        const double lx = std::log(x[i]), ly = std::log(y[i]);
        sx += lx, sy += ly, sxx += lx * lx, sxy += lx * ly, ++n;
    }
    const double d = n * sxx - sx * sx;
    return n >= 2 && d > 1e-12 * std::max(1.0, n * sxx) ? (n * sxy - sx * sy) / d : NAN;
}

Chart growth_chart(const std::vector<GrowthPoint>& points, const std::string& scenes) {
    Chart c;
    c.title = "Per-frame cost against object count";
    c.x_label = "objects";
    c.y_label = "update + ray cast per frame (ms)";
    c.log_x = c.log_y = true;
    struct Fit {
        std::string label;
        double slope;
    };
    std::vector<Fit> fits;
    double largest = 0;
    for (const GrowthPoint& p : points) largest = std::max(largest, p.objects);
    const GrowthPoint *fastest = nullptr, *slowest = nullptr;  // at the largest count
    std::vector<std::string> labels;
    for (const GrowthPoint& p : points)
        if (std::find(labels.begin(), labels.end(), p.label) == labels.end()) labels.push_back(p.label);
    for (const std::string& l : labels) {
        std::vector<std::pair<double, double>> xy;
        int style = 0;
        for (const GrowthPoint& p : points)
            if (p.label == l) {
                xy.emplace_back(p.objects, p.frame_ms);
                style = p.style;
                if (p.objects == largest && p.frame_ms > 0) {
                    if (!fastest || p.frame_ms < fastest->frame_ms) fastest = &p;
                    if (!slowest || p.frame_ms > slowest->frame_ms) slowest = &p;
                }
            }
        std::sort(xy.begin(), xy.end());
        Series s{l, {}, {}, {}, true, style};
        for (auto [x, y] : xy) s.x.push_back(x), s.y.push_back(y);
        const double slope = log_log_slope(s.x, s.y);
        if (std::isfinite(slope)) {
            s.name += " (slope " + fixed(slope, 2) + ")";
            fits.push_back({l, slope});
        }
        c.series.push_back(std::move(s));
    }
    if (fits.empty()) {
        c.reading = "Too few object counts on " + scenes + " to fit slopes.";
        return c;
    }
    const std::string slopes = join(fits, ", ", [](const Fit& f) { return f.label + " " + fixed(f.slope, 2); });
    const auto [flat, steep] =
        std::minmax_element(fits.begin(), fits.end(), [](const Fit& a, const Fit& b) { return a.slope < b.slope; });
    c.reading = "Least-squares slopes of log per-frame cost against log object count on " + scenes +
                " (1 = linear, 0 = constant): " + slopes + ". Flattest growth: " + flat->label + " (" +
                fixed(flat->slope, 2) + "); steepest: " + steep->label + " (" + fixed(steep->slope, 2) + ").";
    if (fastest && slowest && fastest != slowest)
        c.reading += " At " + fixed(largest, 0) + " objects the fastest is " + fastest->label + " (" +
                     fixed(fastest->frame_ms, 3) + " ms per frame), the slowest " + slowest->label + " (" +
                     fixed(slowest->frame_ms, 3) + " ms).";
    return c;
}

}  // namespace rcb
