#include "core/scene/phases.h"

#include <algorithm>
#include <cmath>

#include <nlohmann/json.hpp>

#include "core/base/error.h"

namespace rcb {

FrameWindow measured_window(const Recording& r, const std::string& where) {
    const nlohmann::json meta = nlohmann::json::parse(r.meta, nullptr, false);
    FrameWindow w;
    if (!meta.is_object() || !meta.contains("measure")) return w;
    const nlohmann::json& m = meta["measure"];
    const auto field = [&](const char* key, std::uint32_t& out) {
        if (!m.is_object() || !m.contains(key) || !m[key].is_number_unsigned() || m[key].get<std::uint64_t>() == 0 ||
            m[key].get<std::uint64_t>() > UINT32_MAX)
            throw InputError(where + ": META measure." + key + ": expected a whole number from 1");
        out = std::uint32_t(m[key].get<std::uint64_t>());
    };
    field("first", w.first);
    field("last", w.last);
    field("stride", w.stride);
    return w;
}

std::vector<std::string> motion_phase_names() { return {"falling", "impact", "settling", "asleep"}; }

std::vector<MotionPhase> motion_phases(const Recording& r) {
    const auto n = static_cast<std::uint32_t>(r.frames.size());
    std::vector<double> share(n), motion(n);
    LiveSet live(r.initial);
    for (std::uint32_t f = 0; f < n; ++f) {
        const Frame& frame = r.frames[f];
        const double count = std::max<double>(1, double(live.size()));
        share[f] = double(frame.change_count()) / count;
        double sum = 0;
        for (const Object& o : frame.moves) {
            const Aabbd before = live.box(o.uid).as<double>();
            const Vec3d d = o.box.as<double>().center() - before.center();
            if (before.longest_edge() > 0) sum += std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z) / before.longest_edge();
        }
        motion[f] = sum / count;
        live.apply(frame);
    }
    // Frame indices below are 0-based; the phases' bounds 1-based.
    const std::uint32_t peak = n ? std::uint32_t(std::max_element(motion.begin(), motion.end()) - motion.begin()) : 0;
    std::uint32_t halved = peak + 1;
    while (halved < n && motion[halved] > 0.5 * motion[peak]) ++halved;
    std::uint32_t still = std::min(halved, n);
    while (still < n && share[still] >= kAsleepShare) ++still;
    const std::uint32_t starts[5] = {0, std::min(peak + 1, n), std::min(halved, n), still, n};
    std::vector<MotionPhase> phases;
    const std::vector<std::string> names = motion_phase_names();
    for (std::size_t i = 0; i < names.size(); ++i) {
        MotionPhase p;
        p.name = names[i];
        p.first = starts[i] + 1;
        p.last = starts[i + 1];
        double sum = 0;
        for (std::uint32_t f = starts[i]; f < starts[i + 1]; ++f) sum += share[f];
        if (!p.empty()) p.moving_share = sum / double(p.frames());
        phases.push_back(p);
    }
    return phases;
}

}  // namespace rcb
