#pragma once
/// The motion phases of a recording, found from its moves alone, so that an experiment can measure
/// each phase of a physics scene on its own (engines spend most of their frames with a few moving
/// bodies among many still ones) and `scene info` can show them. Per frame f: the share s_f of the
/// live objects that changed, and the motion m_f, the mean over the live objects of each one's
/// centre displacement over its longest edge (0 for an object that did not move). With p the first
/// frame of the largest m_f:
///
///   falling   frames 1..p: motion builds up to its peak (bodies falling, flung, spreading)
///   impact    from p + 1 until m_f first drops to half the peak (bodies meeting ground and each other)
///   settling  from there until the changed share first drops below 10%
///   asleep    from there to the end: under 10% of the objects move per frame
///
/// A phase the recording never reaches is empty (first > last).
///
/// An experiment measures a window of a recording's frames (a phase, or from a start frame, every
/// stride-th frame): the runner marks it in the recording's META as "measure": {"first", "last",
/// "stride", ...}, and the simulator replays every frame but leaves the others out of the
/// summaries, as it does warm-up frames, so a structure meets each measured frame in the state
/// the frames before left it.

#include <cstdint>
#include <string>
#include <vector>

#include "core/scene/scene.h"

namespace rcb {

inline constexpr double kAsleepShare = 0.1;  ///< the changed share below which a recording is asleep

struct MotionPhase {
    std::string name;
    std::uint32_t first = 1, last = 0;  ///< 1-based frames, inclusive
    double moving_share = 0;            ///< mean changed share over the phase's frames (0 when empty)
    bool empty() const { return first > last; }
    std::uint32_t frames() const { return empty() ? 0 : last - first + 1; }
};

/// Frames first..last (1-based, inclusive), every stride-th from first.
struct FrameWindow {
    std::uint32_t first = 1, last = UINT32_MAX, stride = 1;
    bool contains(std::uint32_t frame) const {
        return frame >= first && frame <= last && (frame - first) % stride == 0;
    }
};
/// The window META's "measure" gives (InputError naming `where` when malformed); every frame
/// without one.
FrameWindow measured_window(const Recording& recording, const std::string& where);

/// falling, impact, settling, asleep.
std::vector<std::string> motion_phase_names();

/// The four phases in order; they cover frames 1..F without overlap.
std::vector<MotionPhase> motion_phases(const Recording& recording);

}  // namespace rcb
