#include "runner/results_writer.h"

#include "runner/sqlite.h"
#include "runner/store.h"

namespace rcb {

void write_fits(Database& db, std::int64_t run, const std::vector<StoredFit>& fits) {
    Transaction t(db);
    db.prepare("DELETE FROM fit WHERE run_id = ?").bind(1, run).run();
    for (const StoredFit& f : fits) {
        db.prepare(
              "INSERT INTO fit(run_id, created_at, structure, target, model, terms, observations, configurations, r2, "
              "rmse_relative, heldout_error, condition_number, status, chosen) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)")
            .bind_all(run, utc_now(), f.structure, f.target, f.model, f.terms, f.observations, f.configurations, f.r2,
                      f.rmse_relative, f.heldout_error, f.condition_number, f.status, std::int64_t(f.chosen))
            .run();
        const std::int64_t fit = db.last_insert_id();
        db.prepare("UPDATE fit SET loso_error = ?, notes = ? WHERE id = ?")
            .bind(1, f.loso_error)
            .bind(2, f.notes)
            .bind(3, fit)
            .run();
        for (const StoredCoefficient& c : f.coefficients) {
            Statement ins = db.prepare(
                "INSERT INTO fit_coefficient(fit_id, name, value, ci_low, ci_high, spans_zero) VALUES (?,?,?,?,?,?)");
            ins.bind_all(fit, c.name, c.value);
            ins.bind(4, c.ci_low);
            ins.bind(5, c.ci_high);
            ins.bind(6, std::int64_t(c.spans_zero));
            ins.run();
        }
    }
    t.commit();
}

void write_validation(Database& db, const ValidationKey& key, const std::vector<StoredValidation>& rows) {
    Transaction t(db);
    db.prepare("DELETE FROM model_validation WHERE run_id = ? AND train_run_uuid = ? AND split = ?")
        .bind_all(key.run, key.train_run_uuid, key.split)
        .run();
    for (const StoredValidation& s : rows) {
        Statement ins = db.prepare(
            "INSERT INTO model_validation(run_id, created_at, train, train_run_uuid, split, splits, structure, cells, "
            "unpredictable, scenes, frame_median, frame_median_low, frame_median_high, frame_p90, frame_p90_low, "
            "frame_p90_high, raycast_median, raycast_median_low, raycast_median_high, raycast_p90, raycast_p90_low, "
            "raycast_p90_high, resamples, seed, models, outside_range) VALUES "
            "(?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
        ins.bind_all(key.run, utc_now(), key.train, key.train_run_uuid, key.split, key.splits, s.structure, s.cells,
                     s.unpredictable, s.scenes);
        int k = 11;
        for (const std::optional<double>& v : s.errors) ins.bind(k++, v);
        ins.bind(k++, key.resamples);
        ins.bind(k++, key.seed);
        ins.bind(k++, s.models);
        ins.bind(k, s.outside_range);
        ins.run();
    }
    t.commit();
}

void write_clustering(Database& db, const StoredClustering& c) {
    Transaction t(db);
    for (const char* table : {"derived_category_scene", "derived_category", "scene_clustering"})
        db.prepare(std::string("DELETE FROM ") + table + " WHERE run_id = ?").bind_all(c.run).run();
    Statement ins = db.prepare(
        "INSERT INTO scene_clustering(run_id, created_at, seed, k, silhouette, clustering) VALUES (?,?,?,?,?,?)");
    ins.bind_all(c.run, utc_now(), c.seed, c.k);
    ins.bind(5, c.silhouette);
    ins.bind(6, c.clustering);
    ins.run();
    for (std::size_t i = 0; i < c.categories.size(); ++i)
        db.prepare("INSERT INTO derived_category(run_id, category, name, scenes, centroid) VALUES (?,?,?,?,?)")
            .bind_all(c.run, std::int64_t(i), c.categories[i].name, c.categories[i].scenes, c.categories[i].centroid)
            .run();
    for (const auto& [scene, category] : c.scene_category)
        db.prepare("INSERT INTO derived_category_scene(run_id, scene_id, category) VALUES (?,?,?)")
            .bind_all(c.run, scene, category)
            .run();
    t.commit();
}

void write_tuning(Database& db, const std::string& name, const std::string& category,
                  const std::vector<StoredTuning>& rows) {
    Transaction t(db);
    db.prepare("DELETE FROM tuning WHERE name = ? AND category = ?").bind_all(name, category).run();
    for (const StoredTuning& r : rows) {
        Statement ins = db.prepare(
            "INSERT INTO tuning(name, category, structure, mode, algorithm, created_at, git_commit, spec, evaluations, "
            "measurements, seconds, stop_reason, on_bound, best_params, best_measured_ms, best_measured_mad, "
            "best_predicted_ms, default_params, default_measured_ms, chosen, accuracy) VALUES "
            "(?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
        ins.bind_all(name, category, r.structure, r.mode, r.algorithm, utc_now(), r.git_commit, r.spec, r.evaluations,
                     r.measurements, r.seconds, r.stop_reason, r.on_bound, r.best_params, r.best_measured_ms,
                     r.best_measured_mad);
        ins.bind(17, r.best_predicted_ms);
        ins.bind(18, r.default_params);
        ins.bind(19, r.default_measured_ms);
        ins.bind(20, std::int64_t(r.chosen));
        ins.bind(21, r.accuracy);
        ins.run();
        const std::int64_t id = db.last_insert_id();
        for (std::size_t i = 0; i < r.evaluation.size(); ++i)
            db.prepare("INSERT INTO tuning_evaluation(tuning_id, i, params, cost_ms, kind) VALUES (?,?,?,?,?)")
                .bind_all(id, std::int64_t(i), r.evaluation[i].params, r.evaluation[i].cost_ms, r.evaluation_kind)
                .run();
    }
    t.commit();
}

}  // namespace rcb
