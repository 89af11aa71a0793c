#include "sim/simulator.h"

#include <tbb/global_control.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <stdexcept>

#include "core/base/error.h"
#include "accel/model/counter_fields.h"
#include "accel/narrow/narrow_phase.h"
#include "sim/cache_sweep.h"
#include "core/scene/phases.h"

namespace rcb {
namespace {

std::atomic<std::uint64_t> timed_phase_count{0};

/// The clock of a configuration's timings (core/base/stopwatch.h): the thread's own time (the
/// lesser of its wall and CPU spans) when all its work runs on the calling thread (TBB allows one
/// thread, or every thread parameter is 1), else the wall time.
TimingClock timing_clock(const nlohmann::json& params) {
    if (tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism) <= 1)
        return TimingClock::thread;
    for (const char* key : {"threads", "cast_threads"})
        if (params.contains(key) && params[key].is_number_integer() && params[key].get<std::int64_t>() > 1)
            return TimingClock::wall;
    return TimingClock::thread;
}

void check_or_throw(const Structure& s, const std::string& name, std::uint32_t frame) {
    try {
        s.check();
    } catch (const std::logic_error& e) {
        throw std::logic_error(name + ": invariant broken after frame " + std::to_string(frame) + ": " + e.what());
    }
}

[[noreturn]] void different_hits(const std::string& name, std::uint32_t frame) {
    throw std::logic_error(name + ": the counting pass reported other hits than the timed pass in frame " +
                           std::to_string(frame));
}

/// A frame's rays as the batches the simulator casts (simulator.h): the whole frame as one batch
/// when its rays ask for one query kind (cast from the frame itself, nothing copied), else one
/// batch per kind present, its rays in recording order, copied out before any timing. Every batch
/// goes through the same timed pass and the same counting pass. The buffers live across frames,
/// so a frame allocates only when it outgrows the frames before.
class FrameBatches {
public:
    void split(const Frame& frame) {
        batches_.clear();
        kinds_ = &frame.kinds;
        const QueryKind first = frame.kinds.empty() ? QueryKind::all : frame.kinds.front();
        if (std::all_of(frame.kinds.begin(), frame.kinds.end(), [first](QueryKind k) { return k == first; })) {
            whole_.rays = frame.rays, whole_.kinds = frame.kinds;
            whole_.result = fresh_result(first, frame.rays.size());
            batches_.push_back(&whole_);
            return;
        }
        for (KindCopy& c : copies_) c.rays.clear(), c.kinds.clear();
        for (std::size_t i = 0; i < frame.rays.size(); ++i) {
            KindCopy& c = copies_[std::size_t(frame.kinds[i])];
            c.rays.push_back(frame.rays[i]);
            c.kinds.push_back(frame.kinds[i]);
        }
        for (int k = 0; k < kQueryKinds; ++k) {
            KindCopy& c = copies_[std::size_t(k)];
            if (c.rays.empty()) continue;
            c.batch.rays = c.rays, c.batch.kinds = c.kinds;
            c.batch.result = fresh_result(QueryKind(k), c.rays.size());
            batches_.push_back(&c.batch);
        }
    }

    /// Each batch cast as one timed call (or, without timing, through the counting pass as the
    /// only cast, which then leaves its counters).
    void timed_pass(Structure& s, bool timed, TimingClock clock) {
        for (Batch* b : batches_) {
            KindResult& r = b->result;
            if (timed) {
                ++timed_phase_count;
                const Stopwatch watch;
                s.cast(b->rays, b->kinds, b->hits);
                r.raycast = watch.elapsed();
                r.raycast_ns = on_clock(r.raycast, clock);
            } else {
                s.cast_counted(b->rays, b->kinds, b->hits, r.counters);
            }
            r.hits = b->hits.uids.size();
        }
        if (!per_kind()) return;
        // Back in recording order: the i-th ray of a kind is that kind's batch's i-th answer.
        merged_.clear();
        std::array<std::size_t, kQueryKinds> next{};
        for (QueryKind k : *kinds_) {
            const std::span<const Uid> answer = copies_[std::size_t(k)].batch.hits.of(next[std::size_t(k)]++);
            merged_.uids.insert(merged_.uids.end(), answer.begin(), answer.end());
            merged_.end_ray();
        }
    }

    /// The frame's answers in recording order, from the last timed pass.
    const HitLists& hits() const { return per_kind() ? merged_ : whole_.hits; }

    /// Each batch again with counters on; its hits must be its timed pass's (the counting policy
    /// must not change what the traversal does).
    void counting_pass(Structure& s, const std::string& name, std::uint32_t frame) {
        for (Batch* b : batches_) {
            s.cast_counted(b->rays, b->kinds, b->counted, b->result.counters);
            if (b->counted.uids != b->hits.uids || b->counted.offsets != b->hits.offsets) different_hits(name, frame);
        }
    }

    /// The batches' times, hits' counters summed into the frame, and their per-kind results (none
    /// for a frame whose rays all ask for all hits).
    void add_to(FrameResult& fr) const {
        for (const Batch* b : batches_) {
            fr.raycast.wall_ns += b->result.raycast.wall_ns;
            fr.raycast.cpu_ns += b->result.raycast.cpu_ns;
            fr.raycast_ns += b->result.raycast_ns;
            fr.counters += b->result.counters;
            if (per_kind() || b->result.kind != QueryKind::all) fr.kinds.push_back(b->result);
        }
    }

private:
    struct Batch {
        std::span<const Segment> rays;
        std::span<const QueryKind> kinds;
        HitLists hits, counted;
        KindResult result;
    };
    struct KindCopy {
        std::vector<Segment> rays;
        std::vector<QueryKind> kinds;
        Batch batch;
    };
    bool per_kind() const { return batches_.empty() || batches_.front() != &whole_; }
    static KindResult fresh_result(QueryKind kind, std::size_t rays) {
        KindResult r;
        r.kind = kind;
        r.rays = static_cast<std::uint32_t>(rays);
        return r;
    }

    Batch whole_;
    std::array<KindCopy, kQueryKinds> copies_;
    std::vector<Batch*> batches_;
    HitLists merged_;
    const std::vector<QueryKind>* kinds_ = nullptr;
};

/// The per-kind block of SimulationResult::to_json: per kind, the median over measured frames of
/// its ray-cast time and of its time per query, and per frame its results (empty for a frame of
/// all hits).
nlohmann::json kinds_json(const std::vector<FrameResult>& frames) {
    nlohmann::json per_frame = nlohmann::json::array(), summary = nlohmann::json::object();
    std::array<std::vector<double>, kQueryKinds> ns, ns_per_query;
    std::array<std::uint64_t, kQueryKinds> rays{};
    for (const FrameResult& f : frames) {
        nlohmann::json here = nlohmann::json::array();
        for (const KindResult& k : f.kinds) {
            nlohmann::json kind = {{"kind", query_kind_name(k.kind)},
                                   {"rays", k.rays},
                                   {"raycast_ns", k.raycast_ns},
                                   {"raycast_wall_ns", k.raycast.wall_ns},
                                   {"hits", k.hits}};
            for (const CounterField& c : kCounterFields) kind[c.name] = k.counters.*c.member;
            here.push_back(kind);
            rays[std::size_t(k.kind)] += k.rays;
            if (f.warmup || k.rays == 0) continue;
            ns[std::size_t(k.kind)].push_back(double(k.raycast_ns));
            ns_per_query[std::size_t(k.kind)].push_back(double(k.raycast_ns) / k.rays);
        }
        per_frame.push_back(here);
    }
    for (int k = 0; k < kQueryKinds; ++k)
        if (rays[std::size_t(k)] > 0)
            summary[kQueryKindNames[k]] = {{"rays", rays[std::size_t(k)]},
                                           {"raycast_ns_median", spread_of(ns[std::size_t(k)]).median},
                                           {"ns_per_query_median", spread_of(ns_per_query[std::size_t(k)]).median}};
    return {{"summary", summary}, {"frames", per_frame}};
}

}  // namespace

std::uint64_t SimulationResult::mismatches() const {
    std::uint64_t total = 0;
    for (const FrameResult& f : frames) total += f.mismatches();
    return total;
}

Spread SimulationResult::update_ns() const {
    std::vector<double> v;
    for (const FrameResult& f : frames)
        if (!f.warmup) v.push_back(double(f.update_ns));
    return spread_of(v);
}

Spread SimulationResult::raycast_ns() const {
    std::vector<double> v;
    for (const FrameResult& f : frames)
        if (!f.warmup) v.push_back(double(f.raycast_ns));
    return spread_of(v);
}

nlohmann::json SimulationResult::to_json() const {
    nlohmann::json j = {
        {"structure", structure},       {"params", params},     {"objects", objects},        {"build_ns", build_ns},
        {"memory_bytes", memory_bytes}, {"verified", verified}, {"mismatches", mismatches()}};
    const Spread u = update_ns(), r = raycast_ns();
    j["update_ns_median"] = u.median;
    j["update_ns_mad"] = u.mad;
    j["raycast_ns_median"] = r.median;
    j["raycast_ns_mad"] = r.mad;
    j["clock"] = clock_name(clock);
    j["cache"] = cold_cache_bytes ? "cold" : "warm";
    if (cold_cache_bytes) j["cache_sweep_bytes"] = cold_cache_bytes;
    nlohmann::json frame, warmup, update, raycast, update_wall, raycast_wall, writes, work, rays, closest, any, hits,
        missed, extra, duplicate, returned, correct, relevant, memory, stats;
    std::array<nlohmann::json, kCounterFields.size()> counted;
    for (const FrameResult& f : frames) {
        frame.push_back(f.frame);
        warmup.push_back(f.warmup);
        update.push_back(f.update_ns);
        raycast.push_back(f.raycast_ns);
        update_wall.push_back(f.update.wall_ns);
        raycast_wall.push_back(f.raycast.wall_ns);
        writes.push_back(f.writes);
        work.push_back(f.update_work);
        rays.push_back(f.rays);
        closest.push_back(f.closest);
        any.push_back(f.any);
        hits.push_back(f.hits);
        missed.push_back(f.missed);
        extra.push_back(f.extra);
        duplicate.push_back(f.duplicate);
        returned.push_back(f.returned);
        correct.push_back(f.correct);
        relevant.push_back(f.relevant);
        for (std::size_t c = 0; c < kCounterFields.size(); ++c)
            counted[c].push_back(f.counters.*kCounterFields[c].member);
        memory.push_back(f.memory_bytes);
        stats.push_back(f.stats);
    }
    auto array = [](nlohmann::json a) { return a.is_null() ? nlohmann::json::array() : a; };
    j["frame"] = array(frame);
    j["warmup"] = array(warmup);
    j["update_ns"] = array(update);
    j["raycast_ns"] = array(raycast);
    j["update_wall_ns"] = array(update_wall);
    j["raycast_wall_ns"] = array(raycast_wall);
    j["writes"] = array(writes);
    j["update_work"] = array(work);
    j["rays"] = array(rays);
    j["rays_closest"] = array(closest);
    j["rays_any"] = array(any);
    j["hits"] = array(hits);
    j["missed"] = array(missed);
    j["extra"] = array(extra);
    j["duplicate"] = array(duplicate);
    j["returned"] = array(returned);
    j["correct"] = array(correct);
    j["relevant"] = array(relevant);
    for (std::size_t c = 0; c < kCounterFields.size(); ++c) j[kCounterFields[c].name] = array(counted[c]);
    j["frame_memory_bytes"] = array(memory);
    j["stats"] = array(stats);
    if (std::any_of(frames.begin(), frames.end(), [](const FrameResult& f) { return !f.kinds.empty(); }))
        j["kinds"] = kinds_json(frames);
    nlohmann::json examples = nlohmann::json::array();
    static const char* kinds[] = {"missed", "extra", "duplicate"};
    for (const auto& [f, d] : this->examples)
        examples.push_back({{"frame", f}, {"ray", d.ray}, {"uid", d.uid}, {"kind", kinds[d.kind]}});
    j["mismatch_examples"] = examples;
    return j;
}

SimulationOptions untimed_replay(std::uint32_t warmup_frames) {
    SimulationOptions o;
    o.verify = false;
    o.timed_cast = false;
    o.timed_update = false;
    o.warmup_frames = warmup_frames;
    return o;
}

std::uint64_t timed_phases() { return timed_phase_count.load(); }

void check_warmup(std::size_t warmup_frames, std::size_t frames) {
    // Warm-up frames are left out of every median: with none left there is nothing to report
    // (a summary of zero frames would read as 0 ns).
    if (warmup_frames > 0 && warmup_frames >= frames)
        throw InputError(std::to_string(warmup_frames) + " warm-up frames leave none of the scene's " +
                         std::to_string(frames) + " frames to measure");
}

SimulationResult simulate(const Recording& recording, const StructureInfo& info, const nlohmann::json& params,
                          const SimulationOptions& options, const std::string& params_path,
                          const FrameCallback& on_frame) {
    const std::size_t frames = options.max_frames ? std::min<std::size_t>(options.max_frames, recording.frames.size())
                                                  : recording.frames.size();
    check_warmup(options.warmup_frames, frames);
    // The window an experiment measures (core/scene/phases.h): other frames run like warm-up ones.
    const FrameWindow window = measured_window(recording, "scene");
    std::size_t measured = 0;
    for (std::size_t i = options.warmup_frames; i < frames; ++i) measured += window.contains(std::uint32_t(i + 1));
    if (measured == 0 && frames > 0)
        throw InputError("the measured frames " + std::to_string(window.first) + ".." + std::to_string(window.last) +
                         " (every " + std::to_string(window.stride) + ") leave none of the scene's " +
                         std::to_string(frames) + " frames after warm-up to measure");
    SimulationResult result;
    result.structure = info.name;
    result.params = info.complete(params, params_path);
    result.verified = options.verify;
    std::unique_ptr<Structure> structure = info.make(params, params_path);
    const Contract contract = contract_of(result.params);

    result.clock = timing_clock(result.params);
    result.cold_cache_bytes = options.cold_cache ? options.cold_cache->bytes() : 0;
    const Stopwatch build_watch;
    structure->build(recording.initial);
    structure->commit();
    if (options.timed_update) result.build_ns = build_watch.ns(result.clock), ++timed_phase_count;
    result.objects = recording.initial.size();
    result.memory_bytes = structure->memory_bytes();
    if (options.check || options.validate) check_or_throw(*structure, info.name, 0);

    LiveSet live(recording.initial);
    FrameBatches batches;
    for (std::size_t i = 0; i < frames; ++i) {
        const Frame& frame = recording.frames[i];
        FrameResult fr;
        fr.frame = static_cast<std::uint32_t>(i + 1);
        fr.warmup = i < options.warmup_frames || !window.contains(std::uint32_t(i + 1));
        fr.inserts = static_cast<std::uint32_t>(frame.inserts.size());
        fr.removes = static_cast<std::uint32_t>(frame.removes.size());
        fr.moves = static_cast<std::uint32_t>(frame.moves.size());
        fr.rays = static_cast<std::uint32_t>(frame.rays.size());
        for (QueryKind k : frame.kinds) {
            fr.closest += k == QueryKind::closest;
            fr.any += k == QueryKind::any;
        }

        const std::uint64_t writes_before = structure->writes(), work_before = structure->update_work();
        if (options.cold_cache) options.cold_cache->sweep();
        const Stopwatch update_watch;
        for (Uid uid : frame.removes) structure->remove(uid);
        for (const Object& o : frame.inserts) structure->insert(o);
        for (const Object& o : frame.moves) structure->move(o);
        structure->commit();
        if (options.timed_update) {
            fr.update = update_watch.elapsed();
            fr.update_ns = on_clock(fr.update, result.clock);
            ++timed_phase_count;
        }
        fr.writes = structure->writes() - writes_before;
        fr.update_work = structure->update_work() - work_before;
        live.apply(frame);
        if (options.check || options.validate) check_or_throw(*structure, info.name, fr.frame);

        batches.split(frame);
        batches.timed_pass(*structure, options.timed_cast, result.clock);
        const HitLists& hits = batches.hits();
        fr.hits = hits.uids.size();

        if (options.verify) {
            const Verification v = GroundTruth(live.objects()).verify(frame.rays, frame.kinds, hits, contract);
            fr.missed = v.missed;
            fr.extra = v.extra;
            fr.duplicate = v.duplicate;
            fr.returned = v.returned;
            fr.correct = v.correct;
            fr.relevant = v.relevant;
            for (const Discrepancy& d : v.examples)
                if (result.examples.size() < 20) result.examples.emplace_back(fr.frame, d);
        }
        if (options.count && options.timed_cast) batches.counting_pass(*structure, info.name, fr.frame);
        batches.add_to(fr);
        fr.memory_bytes = structure->memory_bytes();
        fr.stats = structure->stats();
        if (on_frame) on_frame(fr);
        result.frames.push_back(std::move(fr));
    }
    return result;
}

}  // namespace rcb
