// rcbench cast: a user's own segments against a scene's first frame, as JSON Lines.
#include <algorithm>
#include <iostream>
#include <memory>

#include "core/scene/import/csv.h"
#include "core/scene/recording_io.h"
#include "accel/registry.h"
#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "cli/structure_options.h"

namespace rcb {

void add_cast_command(CLI::App& app) {
    struct Options {
        std::string scene;
        std::string rays;
        StructureOptions structure;
        std::string query_kind = "all";
    };
    auto o = std::make_shared<Options>();
    CLI::App* cmd =
        app.add_subcommand("cast",
                           "Cast your own segments (CSV) against a scene's frame 0: one JSON line of hits per ray\n"
                           "Cast the segments of a CSV file (x0,y0,z0,x1,y1,z1) against a scene's frame 0; "
                           "prints one JSON line per ray: {\"ray\": i, \"hits\": [uid, ...]}");
    cmd->add_option("--query-kind", o->query_kind,
                    "Query kind of every ray: all (every hit, sorted by uid), closest (the nearest hit: smallest "
                    "entry t, then smallest uid) or any (one hit met); closest and any print at most one uid")
        ->capture_default_str()
        ->check(CLI::IsMember({"all", "closest", "any"}));
    add_deprecated_alias(cmd, "--kind", "--query-kind", o->query_kind)->check(CLI::IsMember({"all", "closest", "any"}));
    cmd->add_option("--scene", o->scene, "Recording file, or a boxes CSV (uid,minx,miny,minz,maxx,maxy,maxz)")
        ->required()
        ->check(input_file());
    cmd->add_option("--rays", o->rays, "Rays CSV; ray i is the i-th data line, from 0")
        ->required()
        ->check(input_file());
    add_structure_options(*cmd, o->structure);
    cmd->callback([o] {
        const StructureInfo& info = find_structure(o->structure.name);
        std::unique_ptr<Structure> s = info.make(o->structure.params(), "--param");
        const bool csv = o->scene.size() >= 4 && o->scene.compare(o->scene.size() - 4, 4, ".csv") == 0;
        const std::vector<Object> objects = csv ? read_boxes_csv(o->scene) : read_recording(o->scene).initial;
        const std::vector<Segment> rays = read_rays_csv(o->rays);
        s->build(objects);
        s->commit();
        const auto kind = QueryKind(std::find(std::begin(kQueryKindNames), std::end(kQueryKindNames), o->query_kind) -
                                    std::begin(kQueryKindNames));
        const std::vector<QueryKind> kinds(kind == QueryKind::all ? 0 : rays.size(), kind);
        HitLists hits;
        s->cast(rays, kinds, hits);
        std::vector<Uid> sorted;
        for (std::size_t i = 0; i < rays.size(); ++i) {
            auto h = hits.of(i);
            sorted.assign(h.begin(), h.end());
            std::sort(sorted.begin(), sorted.end());
            std::cout << nlohmann::json{{"ray", i}, {"hits", sorted}}.dump() << '\n';
        }
    });
}

}  // namespace rcb
