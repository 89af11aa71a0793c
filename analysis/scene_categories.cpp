#include "analysis/scene_categories.h"

#include <algorithm>
#include <limits>
#include <map>
#include <numeric>
#include <set>

#include "analysis/cost_model.h"
#include "core/base/error.h"
#include "core/base/number_text.h"
#include "core/base/random.h"
#include "runner/results_reader.h"
#include "runner/results_writer.h"
#include "runner/store.h"

namespace rcb {

using json = nlohmann::json;

FeatureValues FeatureScaling::standardize(const FeatureValues& x) const {
    FeatureValues z{};
    for (std::size_t f = 0; f < kSceneFeatureCount; ++f) z[f] = sd[f] > 0 ? (x[f] - mean[f]) / sd[f] : 0.0;
    return z;
}

namespace {

constexpr double kNoStructure = 0.25;  // mean silhouette below this: one category
constexpr double kDistinctive = 0.5;   // |z| of a centroid that names a category
constexpr std::size_t kRestarts = 10;  // k-means++ starts per k
constexpr std::size_t kMaxIterations = 100;

/// The smallest difference of each feature that means another kind of scene rather than another
/// seed of the same generator (about three times the spread over seeds of one preset), in the order
/// of scene_feature_names(). Standard deviations are floored at these, so that standardising does
/// not magnify noise, and two categories must differ by kSeparation of them in some feature.
constexpr FeatureValues kNoticeable = {0.1, 0.1, 0.1, 0.15, 0.05, 0.1, 0.15, 0.05, 0.05, 0.005};
constexpr double kSeparation = 2;

/// Moves each of `centres` to the mean of the points `assign` gives it; a centre without points stays.
void move_to_means(const std::vector<FeatureValues>& points, const std::vector<std::size_t>& assign,
                   std::vector<FeatureValues>& centres) {
    std::vector<FeatureValues> sum(centres.size(), FeatureValues{});
    std::vector<double> count(centres.size(), 0);
    for (std::size_t i = 0; i < points.size(); ++i) {
        count[assign[i]] += 1;
        for (std::size_t f = 0; f < kSceneFeatureCount; ++f) sum[assign[i]][f] += points[i][f];
    }
    for (std::size_t c = 0; c < centres.size(); ++c)
        if (count[c] > 0)
            for (std::size_t f = 0; f < kSceneFeatureCount; ++f) centres[c][f] = sum[c][f] / count[c];
}

/// True when every two centroids differ by kSeparation noticeable differences in some feature.
bool separated(const std::vector<FeatureValues>& scenes, const std::vector<std::size_t>& assign, std::size_t k) {
    std::vector<FeatureValues> c(k, FeatureValues{});
    move_to_means(scenes, assign, c);
    for (std::size_t a = 0; a < k; ++a)
        for (std::size_t b = a + 1; b < k; ++b) {
            double most = 0;
            for (std::size_t f = 0; f < kSceneFeatureCount; ++f)
                most = std::max(most, std::abs(c[a][f] - c[b][f]) / kNoticeable[f]);
            if (most < kSeparation) return false;
        }
    return true;
}

/// What a low and a high value of each feature mean, for category names.
const std::array<std::pair<const char*, const char*>, kSceneFeatureCount>& feature_words() {
    static const std::array<std::pair<const char*, const char*>, kSceneFeatureCount> words = {{
        {"few-objects", "many-objects"},
        {"small-boxes", "large-boxes"},
        {"even-sizes", "mixed-sizes"},
        {"flat", "deep"},
        {"clustered", "spread-out"},
        {"even-density", "crowded"},
        {"few-hits", "many-hits"},
        {"short-walks", "long-walks"},
        {"short-rays", "long-rays"},
        {"calm", "busy"},
    }};
    return words;
}

double distance2(const FeatureValues& a, const FeatureValues& b) {
    double d = 0;
    for (std::size_t f = 0; f < kSceneFeatureCount; ++f) d += (a[f] - b[f]) * (a[f] - b[f]);
    return d;
}

FeatureScaling scaling_of(const std::vector<SceneFeatures>& scenes) {
    FeatureScaling s;
    const double n = double(scenes.size());
    for (std::size_t f = 0; f < kSceneFeatureCount; ++f) {
        double sum = 0, sq = 0;
        for (const SceneFeatures& x : scenes) sum += x.values[f];
        s.mean[f] = sum / n;
        for (const SceneFeatures& x : scenes) sq += (x.values[f] - s.mean[f]) * (x.values[f] - s.mean[f]);
        s.sd[f] = std::max(std::sqrt(sq / n), kNoticeable[f]);
    }
    return s;
}

struct KMeans {
    std::vector<std::size_t> assignment;
    std::vector<FeatureValues> centres;
    double inertia = std::numeric_limits<double>::infinity();
};

/// Lloyd's iterations from k-means++ starts, best of kRestarts by inertia.
KMeans kmeans(const std::vector<FeatureValues>& z, std::size_t k, std::uint64_t seed) {
    const std::size_t n = z.size();
    KMeans best;
    for (std::size_t restart = 0; restart < kRestarts; ++restart) {
        Random rng(mix_seed(seed, k * 1000 + restart));
        std::vector<FeatureValues> centres{z[rng.below(n)]};
        std::vector<double> d2(n);
        while (centres.size() < k) {
            double total = 0;
            for (std::size_t i = 0; i < n; ++i) {
                d2[i] = std::numeric_limits<double>::infinity();
                for (const FeatureValues& c : centres) d2[i] = std::min(d2[i], distance2(z[i], c));
                total += d2[i];
            }
            std::size_t pick = 0;
            if (total > 0) {
                double u = rng.uniform() * total;
                for (pick = 0; pick + 1 < n && (u -= d2[pick]) >= 0; ++pick) {
                }
                while (d2[pick] == 0 && pick + 1 < n) ++pick;  // never a point that is already a centre
            }
            centres.push_back(z[pick]);
        }
        std::vector<std::size_t> assign(n, 0);
        for (std::size_t it = 0; it < kMaxIterations; ++it) {
            bool changed = it == 0;
            for (std::size_t i = 0; i < n; ++i) {
                std::size_t nearest = 0;
                for (std::size_t c = 1; c < k; ++c)
                    if (distance2(z[i], centres[c]) < distance2(z[i], centres[nearest])) nearest = c;
                changed |= nearest != assign[i];
                assign[i] = nearest;
            }
            if (!changed) break;
            move_to_means(z, assign, centres);
        }
        double inertia = 0;
        for (std::size_t i = 0; i < n; ++i) inertia += distance2(z[i], centres[assign[i]]);
        if (inertia < best.inertia) best = {assign, centres, inertia};
    }
    return best;
}

/// Mean silhouette (Rousseeuw 1987); a scene alone in its cluster scores 0.
double silhouette(const std::vector<FeatureValues>& z, const std::vector<std::size_t>& assign, std::size_t k) {
    const std::size_t n = z.size();
    double total = 0;
    for (std::size_t i = 0; i < n; ++i) {
        std::vector<double> sum(k, 0);
        std::vector<std::size_t> count(k, 0);
        for (std::size_t j = 0; j < n; ++j) {
            if (j == i) continue;
            sum[assign[j]] += std::sqrt(distance2(z[i], z[j]));
            ++count[assign[j]];
        }
        if (count[assign[i]] == 0) continue;
        const double a = sum[assign[i]] / double(count[assign[i]]);
        double b = std::numeric_limits<double>::infinity();
        for (std::size_t c = 0; c < k; ++c)
            if (c != assign[i] && count[c] > 0) b = std::min(b, sum[c] / double(count[c]));
        if (std::isfinite(b) && std::max(a, b) > 0) total += (b - a) / std::max(a, b);
    }
    return total / double(n);
}

/// Categories from their members: centroids, nearest fixed categories and each scene's category.
void fill_categories(SceneClustering& out, const std::vector<SceneFeatures>& scenes,
                     const std::vector<std::vector<std::size_t>>& members, const std::vector<std::string>& fixed) {
    out.categories.clear();
    out.assignment.assign(scenes.size(), 0);
    for (const std::vector<std::size_t>& m : members) {
        DerivedCategory c;
        c.members = m;
        for (std::size_t i : m) {
            out.assignment[i] = out.categories.size();
            for (std::size_t f = 0; f < kSceneFeatureCount; ++f) c.centroid[f] += scenes[i].values[f];
        }
        for (double& v : c.centroid) v /= double(std::max<std::size_t>(m.size(), 1));
        c.z = out.scaling.standardize(c.centroid);
        std::map<std::string, std::size_t> votes;
        for (std::size_t i : m)
            if (i < fixed.size() && !fixed[i].empty()) ++votes[fixed[i]];
        std::size_t most = 0;
        for (const auto& [name, v] : votes)
            if (v > most) most = v, c.nearest_fixed = name;
        out.categories.push_back(c);
    }
}

std::string derived_name(const DerivedCategory& c, std::size_t words) {
    std::vector<std::size_t> order(kSceneFeatureCount);
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return std::abs(c.z[a]) > std::abs(c.z[b]); });
    std::string name = c.nearest_fixed.empty() ? "scenes" : c.nearest_fixed;
    // With several categories the most distinctive feature always names one (a category in the
    // middle of the others has small z-scores but still differs); further ones only when |z| ≥ 0.5.
    for (std::size_t i = 0; i < words && (i == 0 || std::abs(c.z[order[i]]) >= kDistinctive); ++i)
        name +=
            std::string("-") + (c.z[order[i]] < 0 ? feature_words()[order[i]].first : feature_words()[order[i]].second);
    return name;
}

json values_json(const FeatureValues& v) {
    SceneFeatures f;
    f.values = v;
    return f.to_json();
}

FeatureValues values_from(const json& j, const std::string& where) { return SceneFeatures::from_json(j, where).values; }

}  // namespace

SceneClustering cluster_scenes(const std::vector<SceneFeatures>& scenes, const std::vector<std::string>& fixed_of,
                               std::uint64_t seed, std::size_t max_k) {
    if (scenes.empty()) throw InputError("no scenes to derive categories from");
    const std::size_t n = scenes.size();
    SceneClustering out;
    out.seed = seed;
    out.scaling = scaling_of(scenes);
    std::vector<FeatureValues> z;
    for (const SceneFeatures& s : scenes) z.push_back(out.scaling.standardize(s.values));
    std::set<FeatureValues> distinct(z.begin(), z.end());
    std::vector<std::size_t> assign(n, 0);
    std::size_t k = 1;
    if (n <= 2) {
        k = n == 2 && separated({scenes[0].values, scenes[1].values}, {0, 1}, 2) ? 2 : 1;
        for (std::size_t i = 1; i < n; ++i) assign[i] = k == 2 ? 1 : 0;
        out.rule = "k = " + std::to_string(k) + ": " + std::to_string(n) + " scene" + (n == 1 ? "" : "s") +
                   ", too few for a silhouette; " + (k == 2 ? "they differ" : "no two differ") +
                   " by a noticeable amount";
    } else {
        double best = -1;
        const std::size_t top = std::min({max_k, n - 1, distinct.size()});
        std::vector<FeatureValues> raw;
        for (const SceneFeatures& s : scenes) raw.push_back(s.values);
        for (std::size_t kk = 2; kk <= top; ++kk) {
            const KMeans m = kmeans(z, kk, seed);
            if (!separated(raw, m.assignment, kk)) continue;
            const double s = silhouette(z, m.assignment, kk);
            if (s > best + 1e-12) best = s, k = kk, assign = m.assignment;
        }
        if (best < kNoStructure) {
            out.rule = "k = 1: no k in 2.." + std::to_string(top) +
                       " made categories that differ by a noticeable amount with a mean silhouette of at least " +
                       fixed(kNoStructure, 2) + (best >= -1 + 1e-12 ? " (best " + fixed(best, 2) + ")" : "");
            k = 1;
            assign.assign(n, 0);
        } else {
            out.silhouette = best;
            out.rule = "k = " + std::to_string(k) + " of 2.." + std::to_string(top) +
                       " by the highest mean silhouette (" + fixed(best, 2) + ")";
        }
    }
    // Categories ordered by their first scene, so the numbering does not depend on k-means' labels.
    std::vector<std::vector<std::size_t>> members;
    std::map<std::size_t, std::size_t> renumber;
    for (std::size_t i = 0; i < n; ++i) {
        if (!renumber.count(assign[i])) renumber[assign[i]] = members.size(), members.emplace_back();
        members[renumber[assign[i]]].push_back(i);
    }
    fill_categories(out, scenes, members, fixed_of);
    // Names: two distinctive features, three if two categories would share a name, then a number.
    std::map<std::string, std::size_t> used;
    const std::size_t words = out.categories.size() > 1 ? 2 : 0;
    for (DerivedCategory& c : out.categories) {
        c.name = derived_name(c, words);
        for (const DerivedCategory& other : out.categories)
            if (&other != &c && derived_name(other, words) == c.name) c.name = derived_name(c, words + 1);
        if (used[c.name]++) c.name += "-" + std::to_string(used[c.name]);
    }
    return out;
}

SceneClustering group_scenes(const std::vector<SceneFeatures>& scenes, const std::vector<std::string>& names,
                             const std::vector<std::vector<std::size_t>>& members) {
    if (scenes.empty()) throw InputError("no scenes to describe categories by");
    SceneClustering out;
    out.scaling = scaling_of(scenes);
    out.rule = "categories as named in the tuning file";
    fill_categories(out, scenes, members, {});
    for (std::size_t c = 0; c < members.size(); ++c) out.categories[c].name = names[c];
    return out;
}

json SceneClustering::to_json() const {
    json j = {{"seed", seed},
              {"rule", rule},
              {"features", json::array()},
              {"mean", values_json(scaling.mean)},
              {"sd", values_json(scaling.sd)},
              {"categories", json::array()}};
    if (std::isfinite(silhouette)) j["silhouette"] = silhouette;
    for (std::string_view name : scene_feature_names()) j["features"].push_back(std::string(name));
    for (const DerivedCategory& c : categories)
        j["categories"].push_back({{"name", c.name},
                                   {"nearest_fixed", c.nearest_fixed},
                                   {"members", c.members},
                                   {"centroid", values_json(c.centroid)}});
    return j;
}

SceneClustering SceneClustering::from_json(const json& j, const std::string& where) {
    SceneClustering s;
    try {
        s.seed = j.at("seed").get<std::uint64_t>();
        s.rule = j.at("rule").get<std::string>();
        if (j.contains("silhouette")) s.silhouette = j.at("silhouette").get<double>();
        s.scaling.mean = values_from(j.at("mean"), where + ": mean");
        s.scaling.sd = values_from(j.at("sd"), where + ": sd");
        for (const json& c : j.at("categories")) {
            DerivedCategory d;
            d.name = c.at("name").get<std::string>();
            d.nearest_fixed = c.at("nearest_fixed").get<std::string>();
            d.members = c.at("members").get<std::vector<std::size_t>>();
            d.centroid = values_from(c.at("centroid"), where + ": category " + d.name);
            d.z = s.scaling.standardize(d.centroid);
            s.categories.push_back(d);
        }
    } catch (const json::exception&) {
        throw InputError(where + ": malformed scene categories (rcbench tune writes them)");
    }
    if (s.categories.empty()) throw InputError(where + ": no scene categories");
    for (std::size_t c = 0; c < s.categories.size(); ++c)
        for (std::size_t i : s.categories[c].members) {
            if (s.assignment.size() <= i) s.assignment.resize(i + 1, 0);
            s.assignment[i] = c;
        }
    return s;
}

CategoryMatch nearest_category(const SceneClustering& c, const SceneFeatures& scene) {
    if (c.categories.empty()) throw InputError("no categories to match a scene to");
    const FeatureValues z = c.scaling.standardize(scene.values);
    std::vector<std::pair<double, std::size_t>> d;
    for (std::size_t i = 0; i < c.categories.size(); ++i) d.push_back({std::sqrt(distance2(z, c.categories[i].z)), i});
    std::stable_sort(d.begin(), d.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    CategoryMatch m;
    m.category = d[0].second;
    m.distance = d[0].first;
    if (d.size() > 1) m.runner_up = d[1].second, m.runner_up_distance = d[1].first;
    const DerivedCategory& cat = c.categories[m.category];
    auto deviation = [&](std::size_t f) {
        return FeatureDeviation{f, scene.values[f], cat.centroid[f], z[f], cat.z[f]};
    };
    std::vector<std::size_t> order;
    for (std::size_t f = 0; f < kSceneFeatureCount; ++f)
        if (c.scaling.sd[f] > 0) order.push_back(f);
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return std::abs(cat.z[a]) > std::abs(cat.z[b]); });
    for (std::size_t i = 0; i < order.size() && i < 3; ++i) m.defining.push_back(deviation(order[i]));
    double gap = -1;
    for (std::size_t f : order)
        if (std::abs(z[f] - cat.z[f]) > gap) gap = std::abs(z[f] - cat.z[f]), m.largest_gap = deviation(f);
    return m;
}

std::string explain_match(const SceneClustering& c, const CategoryMatch& m) {
    auto z_text = [](double z) { return std::string(z >= 0 ? "+" : "") + fixed(z, 1); };
    auto dev = [&](const FeatureDeviation& d) {
        return std::string(scene_feature_names()[d.feature]) + " " + fixed(d.scene, 3) + " (z " + z_text(d.z_scene) +
               ") vs " + fixed(d.centroid, 3) + " (z " + z_text(d.z_centroid) + ")";
    };
    std::string out =
        "category " + c.categories[m.category].name + ": nearest centroid, " + fixed(m.distance, 2) + " sd away";
    if (m.runner_up)
        out += " (next: " + c.categories[*m.runner_up].name + " at " + fixed(m.runner_up_distance, 2) + " sd)";
    if (!m.defining.empty()) {
        out +=
            ". The features that set the category apart, this scene vs its centroid (z: standardised over the "
            "clustered scenes): ";
        for (std::size_t i = 0; i < m.defining.size(); ++i) out += (i ? "; " : "") + dev(m.defining[i]);
    }
    if (m.largest_gap)
        out += ". Largest difference: " + dev(*m.largest_gap) + ", " +
               fixed(std::abs(m.largest_gap->z_scene - m.largest_gap->z_centroid), 1) + " sd";
    return out + ".";
}

RunCategories derive_run_categories(Database& db, std::int64_t run, std::uint64_t seed, std::size_t max_k) {
    RunCategories out;
    out.run = run;
    std::vector<SceneFeatures> features;
    std::vector<std::string> fixed_categories;
    for (const RunSceneRow& scene : read_run_scenes(db, run)) {
        const std::optional<SceneFeatures> f = stored_scene_features(db, scene.id);
        if (!f)
            throw InputError(db.path() + ": scene \"" + scene.label + "\" of run " + std::to_string(run) +
                             " has no stored features (stored by an older rcbench); run the experiment again");
        out.scene_ids.push_back(scene.id);
        out.scene_names.push_back(scene.label);
        features.push_back(*f);
        fixed_categories.push_back(scene_category(scene.spec));
    }
    if (features.empty()) throw InputError(db.path() + ": run " + std::to_string(run) + " has no scenes");
    out.clustering = cluster_scenes(features, fixed_categories, seed, max_k);
    return out;
}

void store_run_categories(Database& db, const RunCategories& rc) {
    const SceneClustering& c = rc.clustering;
    StoredClustering out{rc.run,
                         std::int64_t(c.seed),
                         std::int64_t(c.categories.size()),
                         std::isfinite(c.silhouette) ? std::optional<double>(c.silhouette) : std::nullopt,
                         c.to_json().dump(),
                         {},
                         {}};
    for (const auto& category : c.categories)
        out.categories.push_back(
            {category.name, std::int64_t(category.members.size()), values_json(category.centroid).dump()});
    for (std::size_t i = 0; i < rc.scene_ids.size(); ++i)
        out.scene_category.emplace_back(rc.scene_ids[i], std::int64_t(c.assignment[i]));
    write_clustering(db, out);
}

}  // namespace rcb
