#include "core/scene/workload.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <utility>

#include "core/base/statistics.h"

namespace rcb {

double SceneWorkload::kind_share(QueryKind kind) const {
    const std::size_t n = rays();
    return n ? double(rays_by_kind[int(kind)]) / double(n) : 0.0;
}

std::string SceneWorkload::kinds_text() const {
    if (rays() == 0) return "no rays";
    std::vector<std::pair<std::size_t, int>> order;
    for (int k = 0; k < kQueryKinds; ++k)
        if (rays_by_kind[k]) order.emplace_back(rays_by_kind[k], k);
    std::stable_sort(order.begin(), order.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    std::string out;
    for (const auto& [count, k] : order) {
        char share[32];
        std::snprintf(share, sizeof share, "%.1f%%", 100.0 * double(count) / double(rays()));
        out += (out.empty() ? "" : ", ") + std::string(kQueryKindNames[k]) + " " + share;
    }
    return out;
}

nlohmann::json SceneWorkload::to_json() const {
    nlohmann::json counts = nlohmann::json::object(), shares = nlohmann::json::object();
    for (int k = 0; k < kQueryKinds; ++k) {
        counts[kQueryKindNames[k]] = rays_by_kind[k];
        shares[kQueryKindNames[k]] = kind_share(QueryKind(k));
    }
    return {{"frames", frames},
            {"query_kinds", counts},
            {"query_shares", shares},
            {"rays_per_frame", rays_per_frame},
            {"changes_per_frame", changes_per_frame},
            {"inserts", inserts},
            {"removes", removes},
            {"moves", moves},
            {"motion",
             {{"changed_share", {{"p10", changed_p10}, {"p50", changed_p50}, {"p90", changed_p90}}},
              {"first_frames", first_frames},
              {"last_frames", last_frames},
              {"move_over_size", {{"median", move_median}, {"p90", move_p90}, {"moves", measured_moves}}}}}};
}

SceneWorkload scene_workload(const Recording& r) {
    SceneWorkload w;
    w.frames = r.frames.size();
    LiveSet live(r.initial);
    std::vector<double> shares, steps;
    std::size_t changes = 0, rays = 0;
    for (const Frame& f : r.frames) {
        for (std::size_t i = 0; i < f.rays.size(); ++i) ++w.rays_by_kind[int(f.kind(i))];
        rays += f.rays.size(), changes += f.change_count();
        w.inserts += f.inserts.size(), w.removes += f.removes.size(), w.moves += f.moves.size();
        shares.push_back(live.size() ? double(f.change_count()) / double(live.size()) : 0.0);
        for (const Object& o : f.moves) {
            const Aabbd before = live.box(o.uid).as<double>();
            const Vec3d d = o.box.as<double>().center() - before.center();
            if (before.longest_edge() > 0)
                steps.push_back(std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z) / before.longest_edge());
        }
        live.apply(f);
    }
    const double frames = std::max<double>(1, double(w.frames));
    w.rays_per_frame = double(rays) / frames;
    w.changes_per_frame = double(changes) / frames;
    for (std::size_t i = 0; i < shares.size() && i < 3; ++i) w.first_frames.push_back(shares[i]);
    for (std::size_t i = shares.size() > 3 ? shares.size() - 3 : 0; i < shares.size(); ++i)
        w.last_frames.push_back(shares[i]);
    // A scene without frames or moves reads 0, not NaN.
    const auto q = [](const std::vector<double>& v, double p) { return v.empty() ? 0.0 : quantile(v, p); };
    w.changed_p10 = q(shares, 0.1), w.changed_p50 = q(shares, 0.5), w.changed_p90 = q(shares, 0.9);
    w.move_median = q(steps, 0.5), w.move_p90 = q(steps, 0.9);
    w.measured_moves = steps.size();
    return w;
}

}  // namespace rcb
