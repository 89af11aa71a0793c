// The rcbench binary as a user runs it: exit codes, one-line errors, outputs.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>

#include <nlohmann/json.hpp>

#include "tests/subprocess.h"
#include "tests/test_support.h"

namespace {

namespace fs = std::filesystem;
using test::Outcome;

class Cli : public ::testing::Test {
protected:
    Outcome run(const std::string& args) { return test::run_shell(std::string(RCBENCH_BINARY) + " " + args); }
    std::string path(const std::string& name) const { return dir_.file(name); }
    void write(const std::string& name, const std::string& text) const { std::ofstream(path(name)) << text; }

    rcb::test::TempDir dir_{"cli"};  // rcb_cli_<pid>_<test>, removed after the test
};

/// Bad input: exit 2 and exactly one line on stderr containing `needle`.
void expect_bad_input(const Outcome& r, const std::string& needle) {
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_NE(r.err.find(needle), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

TEST_F(Cli, GenerateInspectSimulateAsJson) {
    const std::string scene = path("s.rcbscene");
    ASSERT_EQ(run("scene gen --preset irreg-s --frames 3 --rays 50 --seed 9 -o " + scene).code, 0);
    const Outcome info = run("scene info --json " + scene);
    ASSERT_EQ(info.code, 0) << info.err;
    const auto i = nlohmann::json::parse(info.out);
    EXPECT_EQ(i["objects"], 99);
    EXPECT_EQ(i["frames"], 3);
    EXPECT_EQ(i["meta"]["seed"], 9);
    const Outcome sim = run("simulate --scene " + scene + " --structure bf --json");
    ASSERT_EQ(sim.code, 0) << sim.err;
    const auto j = nlohmann::json::parse(sim.out);
    EXPECT_EQ(j["structure"], "bf");
    EXPECT_EQ(j["mismatches"], 0);
    EXPECT_EQ(j["raycast_ns"].size(), 3u);
    EXPECT_EQ(j["n_rb"].size(), 3u);
    const Outcome table = run("simulate --scene " + scene + " --structure bf");
    EXPECT_NE(table.out.find("0 mismatches"), std::string::npos) << table.out;
}

TEST_F(Cli, SameSeedGivesTheSameFile) {
    ASSERT_EQ(run("scene gen --preset uni-s --frames 2 -o " + path("a.rcbscene")).code, 0);
    ASSERT_EQ(run("scene gen --preset uni-s --frames 2 -o " + path("b.rcbscene")).code, 0);
    std::ifstream a(path("a.rcbscene"), std::ios::binary), b(path("b.rcbscene"), std::ios::binary);
    EXPECT_EQ(std::string(std::istreambuf_iterator<char>(a), {}), std::string(std::istreambuf_iterator<char>(b), {}));
}

TEST_F(Cli, ImportCsvAndCastOwnRays) {
    write("boxes.csv", "uid,minx,miny,minz,maxx,maxy,maxz\n10,0,0,0,1,1,1\n11,2,0,0,3,1,1\n12,0,5,0,1,6,1\n");
    write("rays.csv", "x0,y0,z0,x1,y1,z1\n-1,0.5,0.5,4,0.5,0.5\n0.5,-1,0.5,0.5,7,0.5\n9,9,9,9,9,9\n");
    const Outcome cast = run("cast --scene " + path("boxes.csv") + " --rays " + path("rays.csv") + " --structure bf");
    ASSERT_EQ(cast.code, 0) << cast.err;
    EXPECT_EQ(cast.out, "{\"hits\":[10,11],\"ray\":0}\n{\"hits\":[10,12],\"ray\":1}\n{\"hits\":[],\"ray\":2}\n");
    const Outcome imp = run("scene import " + path("boxes.csv") + " --frames 4 --rays 10 -o " + path("i.rcbscene"));
    ASSERT_EQ(imp.code, 0) << imp.err;
    const Outcome sim = run("simulate --scene " + path("i.rcbscene") + " --structure bf --json");
    ASSERT_EQ(sim.code, 0) << sim.err;
    EXPECT_EQ(nlohmann::json::parse(sim.out)["frame"].size(), 4u);
}

// The old names of this release's renamed options and keys (simulate --validate, scene gen --kind,
// cast --kind, a scene's "kind") still work as their new names do, each with one line on stderr
// that names the new one, and --help says they are deprecated.
TEST_F(Cli, OldNamesWorkAsTheNewOnesAndSayTheyAreDeprecated) {
    const std::string gen = "scene gen --objects 40 --frames 2 --rays 20 --seed 5 -o ";
    const Outcome fresh = run(gen + path("new.rcbscene") + " --generator uniform");
    ASSERT_EQ(fresh.code, 0) << fresh.err;
    EXPECT_EQ(fresh.err, "");
    const Outcome old = run(gen + path("old.rcbscene") + " --kind uniform");
    ASSERT_EQ(old.code, 0) << old.err;
    EXPECT_EQ(old.err, "rcbench: --kind is deprecated; use --generator\n");
    std::ifstream a(path("new.rcbscene"), std::ios::binary), b(path("old.rcbscene"), std::ios::binary);
    EXPECT_EQ(std::string(std::istreambuf_iterator<char>(a), {}), std::string(std::istreambuf_iterator<char>(b), {}));
    expect_bad_input(run(gen + path("x.rcbscene") + " --kind cubes"), "--kind: cubes not in");

    const std::string sim = "simulate --scene " + path("new.rcbscene") + " --structure dbvh --json ";
    const Outcome checked = run(sim + "--check"), validated = run(sim + "--validate");
    ASSERT_EQ(checked.code, 0) << checked.err;
    ASSERT_EQ(validated.code, 0) << validated.err;
    EXPECT_EQ(checked.err, "");
    EXPECT_EQ(validated.err, "rcbench: --validate is deprecated; use --check\n");
    EXPECT_EQ(nlohmann::json::parse(checked.out)["n_rb"], nlohmann::json::parse(validated.out)["n_rb"]);

    write("boxes.csv", "uid,minx,miny,minz,maxx,maxy,maxz\n10,0,0,0,1,1,1\n11,2,0,0,3,1,1\n");
    write("rays.csv", "x0,y0,z0,x1,y1,z1\n-1,0.5,0.5,4,0.5,0.5\n");
    const std::string cast = "cast --scene " + path("boxes.csv") + " --rays " + path("rays.csv") + " --structure bf ";
    const Outcome query_kind = run(cast + "--query-kind closest"), kind = run(cast + "--kind closest");
    ASSERT_EQ(query_kind.code, 0) << query_kind.err;
    ASSERT_EQ(kind.code, 0) << kind.err;
    EXPECT_EQ(query_kind.out, "{\"hits\":[10],\"ray\":0}\n");
    EXPECT_EQ(kind.out, query_kind.out);
    EXPECT_EQ(query_kind.err, "");
    EXPECT_EQ(kind.err, "rcbench: --kind is deprecated; use --query-kind\n");

    const std::string scene = R"({"objects": 40, "frames": 2, "rays_per_frame": 20, ")";
    write("new.json",
          R"({"name": "x", "structures": [{"name": "bf"}], "scenes": [)" + scene + R"(generator": "uniform"}]})");
    write("old.json",
          R"({"name": "x", "structures": [{"name": "bf"}], "scenes": [)" + scene + R"(kind": "uniform"}]})");
    const Outcome plan = run("run " + path("new.json") + " --dry-run"),
                  old_plan = run("run " + path("old.json") + " --dry-run");
    ASSERT_EQ(plan.code, 0) << plan.err;
    ASSERT_EQ(old_plan.code, 0) << old_plan.err;
    EXPECT_EQ(plan.err, "");
    EXPECT_EQ(old_plan.err, "rcbench: " + path("old.json") + ": scenes[0].kind is deprecated; use \"generator\"\n");
    EXPECT_EQ(old_plan.out, plan.out);

    EXPECT_NE(run("simulate --help").out.find("Deprecated: use --check"), std::string::npos);
    EXPECT_NE(run("scene gen --help").out.find("Deprecated: use --generator"), std::string::npos);
    EXPECT_NE(run("cast --help").out.find("Deprecated: use --query-kind"), std::string::npos);
}

TEST_F(Cli, BadInputIsOneLineAndExitTwo) {
    const std::string scene = path("s.rcbscene");
    ASSERT_EQ(run("scene gen --preset uni-s --frames 1 -o " + scene).code, 0);
    expect_bad_input(run("simulate --scene " + scene + " --structure kdtree"), "unknown structure 'kdtree'");
    expect_bad_input(run("simulate --scene " + path("missing.rcbscene") + " --structure bf"),
                     "--scene: no such file: " + path("missing.rcbscene"));
    expect_bad_input(run("simulate --scene " + scene + " --structure bf --param depth=3"),
                     "--param.depth: unknown parameter of bf");
    expect_bad_input(run("scene gen --preset uni-xxl -o " + path("x")), "--preset: uni-xxl not in {uni-s,");
    expect_bad_input(run("scene gen --generator cubes --objects 10 -o " + path("x")),
                     "--generator: cubes not in {uniform,irregular,jittered,clusters,stadium,");
    expect_bad_input(run("scene gen --preset uni-s --ray-mix sideways -o " + path("x")), "unknown mode 'sideways'");
    expect_bad_input(run("scene gen --preset uni-s --frames abc -o " + path("x")), "--frames");
    expect_bad_input(run("simulate --structure bf"), "--scene is required");
    write("corrupt.rcbscene", "RCBSCENE garbage");
    expect_bad_input(run("scene info " + path("corrupt.rcbscene")), "corrupt.rcbscene");
    write("rays.csv", "0,0,0,1,1,nan\n");
    expect_bad_input(run("cast --scene " + scene + " --rays " + path("rays.csv") + " --structure bf"),
                     "rays.csv:1: non-finite coordinate");
    write("boxes.csv", "1,0,0,0,1,1,1\n1,0,0,0,1,1,1\n");
    expect_bad_input(run("scene import " + path("boxes.csv") + " -o " + path("y")), "boxes.csv:2: duplicate uid 1");
}

TEST_F(Cli, RunQueryCompareRejectBadInputInOneLine) {
    write("bad.json", R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf", "params": {"x": 1}}]})");
    expect_bad_input(run("run " + path("bad.json") + " --db " + path("r.db")),
                     "bad.json: structures[0].params.x: unknown parameter of bf");
    EXPECT_FALSE(fs::exists(path("r.db")));  // nothing written for an invalid file
    write("ok.json",
          R"({"frames": 2, "rays_per_frame": 10, "scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}]})");
    expect_bad_input(run("run " + path("ok.json") + " --shard 0/3 --db " + path("r.db")), "--shard 0/3: expected K/N");
    expect_bad_input(run("run " + path("missing.json")), "experiment: no such file: " + path("missing.json"));
    ASSERT_EQ(run("run " + path("ok.json") + " --db " + path("r.db")).code, 0);
    expect_bad_input(run("query " + path("r.db") + " \"DELETE FROM cell\""), "only read-only statements");
    expect_bad_input(run("query " + path("r.db") + " \"SELECT nope FROM cell\""), "r.db: no such column: nope");
    expect_bad_input(run("query " + path("none.db") + " \"SELECT 1\""), "db: no such file: " + path("none.db"));
    expect_bad_input(run("compare " + path("r.db") + " --baseline 1 --candidate 7"), "no run matches '7'");
    const Outcome csv =
        run("query --csv " + path("r.db") + " \"SELECT structure, count(*) AS cells FROM cell_summary GROUP BY 1\"");
    EXPECT_EQ(csv.out, "structure,cells\nbf,1\n");
}

TEST_F(Cli, HelpTellsTheSubcommands) {
    const Outcome help = run("--help");
    EXPECT_EQ(help.code, 0);
    for (const char* sub : {"scene", "simulate", "cast", "structures", "run", "query", "compare", "merge"})
        EXPECT_NE(help.out.find(sub), std::string::npos) << sub;
    const Outcome structures = run("structures --json");
    EXPECT_EQ(structures.code, 0);
    EXPECT_EQ(nlohmann::json::parse(structures.out)[0]["name"], "bf");
}

/// Characters in a line of UTF-8 (continuation bytes are not characters).
std::size_t characters(const std::string& line) {
    return std::size_t(
        std::count_if(line.begin(), line.end(), [](char c) { return (static_cast<unsigned char>(c) & 0xC0) != 0x80; }));
}

TEST_F(Cli, HelpListsEachSubcommandOnOneShortLineAndItsOwnHelpHoldsTheWholeDescription) {
    const Outcome help = run("--help");
    ASSERT_EQ(help.code, 0) << help.err;
    std::map<std::string, std::string> summary;  // subcommand -> its line in rcbench --help
    std::istringstream lines(help.out);
    const std::regex entry(R"(  ([a-z]+) +(\S.*))");
    bool listing = false;
    for (std::string line; std::getline(lines, line);) {
        EXPECT_LE(characters(line), 100u) << line;
        if (line.empty()) continue;
        std::smatch m;
        if (line == "Subcommands:")
            listing = true;
        else if (listing && std::regex_match(line, m, entry))
            summary[m[1]] = m[2];
        else if (listing)
            ADD_FAILURE() << "not one line per subcommand: " << line;
    }
    EXPECT_GE(summary.size(), 17u) << help.out;
    // The paragraphs rcbench --help printed before: each now in its own subcommand's help alone.
    const std::map<std::string, std::string> paragraph{
        {"validate", "predict every cell of the test run from its counters"},
        {"fit", "choose the smallest adequate model by held-out error"},
        {"tune", "a pattern search with NLopt's DIRECT"},
        {"merge", "fit the merged runs again"},
        {"compare", "Mann-Whitney U p-value"},
        {"advise", "timing nothing"}};
    for (const auto& [sub, words] : paragraph) {
        EXPECT_EQ(help.out.find(words), std::string::npos) << sub;
        const Outcome own = run(sub + " --help");
        EXPECT_NE(own.out.substr(0, own.out.find("Usage:")).find(words), std::string::npos) << sub << own.out;
    }
    for (const auto& [sub, line] : summary) {
        const Outcome own = run(sub + " --help");
        EXPECT_EQ(own.code, 0) << sub << own.err;
        EXPECT_EQ(own.out.rfind(line + "\n", 0), 0u) << sub << ": its help starts with its line\n" << own.out;
    }
}

/// The file's bytes, to check a failed command left it as it was.
std::string bytes_of(const std::string& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST_F(Cli, AnOutputPathThatIsAnInputOrADirectoryIsRefusedAndNothingIsTouched) {
    write("ok.json",
          R"({"frames": 2, "rays_per_frame": 10, "scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}]})");
    ASSERT_EQ(run("run " + path("ok.json") + " --db " + path("res.db")).code, 0);
    const std::string db = bytes_of(path("res.db"));
    expect_bad_input(run("report " + path("res.db") + " -o " + path("res.db")), "is also an input");
    EXPECT_EQ(bytes_of(path("res.db")), db);
    ASSERT_EQ(run("scene gen --preset uni-s --frames 2 -o " + path("s.rcbscene")).code, 0);
    const std::string scene = bytes_of(path("s.rcbscene"));
    expect_bad_input(run("simulate --scene " + path("s.rcbscene") + " --structure bf --json-out " + path("s.rcbscene")),
                     "--json-out " + path("s.rcbscene") + ": is also an input");
    expect_bad_input(run("scene import " + path("s.rcbscene") + " -o " + path("s.rcbscene")), "is also an input");
    EXPECT_EQ(bytes_of(path("s.rcbscene")), scene);
    fs::create_directories(path("adir"));
    expect_bad_input(run("report " + path("res.db") + " -o " + path("adir")), "adir: is a directory");
    EXPECT_FALSE(fs::exists(path("adir.tmp")));
    expect_bad_input(run("tune " + std::string(RCBENCH_SOURCE_DIR) + "/experiments/tune-grids.json --db " +
                         path("t.db") + " --out-dir /proc/self"),
                     "--out-dir /proc/self/tuning-grids.md: cannot write in /proc/self");
    const Outcome full = run("simulate --scene " + path("s.rcbscene") + " --structure bf --json-out /dev/full");
    EXPECT_EQ(full.code, 1);
    EXPECT_NE(full.err.find("/dev/full: write failed"), std::string::npos) << full.err;
}

TEST_F(Cli, NumbersOutsideTheirRangeAreRefusedByName) {
    const std::string out = " -o " + path("x.rcbscene");
    expect_bad_input(run("scene gen --preset uni-s --seed -1" + out), "--seed: expected a whole number");
    expect_bad_input(run("scene gen --preset uni-s --seed 18446744073709551616" + out),
                     "--seed: expected a whole number");
    expect_bad_input(run("scene gen --preset uni-s --change-fraction nan" + out),
                     "--change-fraction: expected a number in 0..1, got nan");
    expect_bad_input(run("scene gen --preset uni-s --move-scale nan" + out),
                     "--move-scale: expected a number in 0..1000, got nan");
    expect_bad_input(run("scene gen --preset uni-s --objects 100000000" + out),
                     "--objects: expected a whole number in 1..67108864");
    expect_bad_input(run("scene gen --preset uni-s --rays 100000000 --frames 100" + out),
                     "the recording could take 250 GB on disk");
    EXPECT_FALSE(fs::exists(path("x.rcbscene")));
    write("ok.json",
          R"({"frames": 2, "rays_per_frame": 10, "scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}]})");
    expect_bad_input(run("run " + path("ok.json") + " --shard 1/18446744073709551616 --db " + path("r.db")),
                     "--shard 1/18446744073709551616");
    ASSERT_EQ(run("scene gen --preset uni-s --frames 3" + out).code, 0);
    // Warm-up that leaves no measured frame: an error, not a table of 0 ns medians.
    expect_bad_input(run("simulate --scene " + path("x.rcbscene") + " --structure bf --warmup 3"),
                     "x.rcbscene: 3 warm-up frames leave none of the scene's 3 frames to measure");
    expect_bad_input(run("advise " + path("x.rcbscene") + " --warmup 5"), "warm-up frames leave none");
}

TEST_F(Cli, AFileThatIsNotADatabaseFailsAtOnceNamingIt) {
    write("junk.db", std::string(100000, 'j'));
    const std::string junk = bytes_of(path("junk.db"));
    write("ok.json",
          R"({"frames": 2, "rays_per_frame": 10, "scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}]})");
    for (const std::string& command :
         {"fit " + path("junk.db"), "run " + path("ok.json") + " --db " + path("junk.db"),
          "query " + path("junk.db") + " \"SELECT 1\"", "report " + path("junk.db") + " -o " + path("r.html")}) {
        const Outcome r = run(command);
        expect_bad_input(r, "junk.db: damaged or not an SQLite database");
        // The lock-retry loop used to retry this for 61 s. Half that: a wall time, so a bound with
        // room for a sanitized build niced beside busy processes (the failure itself takes ms).
        EXPECT_LT(r.seconds, 30) << command;
    }
    EXPECT_EQ(bytes_of(path("junk.db")), junk);
}

TEST_F(Cli, AnExplicitZeroOrEmptyValueIsRefusedNotReadAsTheDefault) {
    write("ok.json",
          R"({"frames": 2, "rays_per_frame": 10, "scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}]})");
    ASSERT_EQ(run("run " + path("ok.json") + " --db " + path("r.db")).code, 0);
    // Leaving --run out means the newest run; --run 0 is no run at all.
    for (const char* command : {"categories", "fit", "findings"})
        expect_bad_input(run(std::string(command) + " " + path("r.db") + " --run 0"),
                         "--run: expected a whole number in 1..");
    expect_bad_input(run("run " + path("ok.json") + " --db " + path("r.db") + " --run 0"), "--run");
    expect_bad_input(run("fit " + path("r.db") + " --experiment ''"), "--experiment: must not be empty");
    expect_bad_input(run("history " + path("r.db") + " --structure ''"), "--structure: must not be empty");
    ASSERT_EQ(run("scene gen --preset uni-s --frames 3 -o " + path("s.rcbscene")).code, 0);
    expect_bad_input(run("advise " + path("s.rcbscene") + " --category ''"), "--category: must not be empty");
}

// findings reads independent runs of one experiment: the same run twice, or runs of two experiments,
// would pass off one measurement as two or mix unlike scenes, so each is refused in one line.
TEST_F(Cli, FindingsReadsSeveralRunsOfOneExperimentAndRefusesTheSameRunTwice) {
    const std::string spec =
        R"("frames": 2, "rays_per_frame": 10, "scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}]})";
    write("a.json", R"({"name": "a", )" + spec);
    write("b.json", R"({"name": "b", )" + spec);
    ASSERT_EQ(run("run " + path("a.json") + " --db " + path("r.db")).code, 0);
    ASSERT_EQ(run("run " + path("a.json") + " --db " + path("r.db") + " --new-run").code, 0);
    ASSERT_EQ(run("run " + path("b.json") + " --db " + path("o.db")).code, 0);
    const Outcome two = run("findings " + path("r.db") + ":1 " + path("r.db") + ":2");
    EXPECT_EQ(two.code, 0) << two.err;
    EXPECT_NE(two.out.find("from 2 independent runs of experiment `a`"), std::string::npos) << two.out;
    expect_bad_input(run("findings " + path("r.db") + ":1 " + path("r.db") + ":1"), "is given twice");
    expect_bad_input(run("findings " + path("r.db") + " " + path("o.db")), "give runs of one experiment");
    expect_bad_input(run("findings " + path("r.db") + ":1 --run 2"), "--run 2: give one database without :RUN");
    expect_bad_input(run("findings " + path("r.db") + ":7"), "no run 7 in");
}

TEST_F(Cli, ARunRefusedAtItsFirstSceneWritesOneLineNamingTheOptionAndTheFile) {
    ASSERT_EQ(run("scene gen --preset uni-s --frames 1 --rays 10 -o " + path("one.rcbscene")).code, 0);
    write("w.json",
          R"({"warmup_frames": 1, "scenes": [{"recording": "one.rcbscene"}], "structures": [{"name": "bf"}]})");
    const Outcome r = run("run " + path("w.json") + " --db " + path("r.db"));
    // Before, a progress line came first, and the message named neither the option nor the file.
    expect_bad_input(r, path("w.json") +
                            ": warmup_frames: 1 warm-up frames leave none of the scene's 1 frames to "
                            "measure (scenes[0]: scene one, " +
                            path("one.rcbscene") + ")");
}

TEST_F(Cli, TheSecondOfTwoNamesForOneSceneIsRefusedBeforeAnythingRuns) {
    write("dup.json", R"({"frames": 2, "rays_per_frame": 10, "scenes": [{"preset": "uni-s", "name": "a"},
                          {"preset": "uni-s", "name": "b"}], "structures": [{"name": "bf"}]})");
    expect_bad_input(run("run " + path("dup.json") + " --db " + path("r.db")),
                     "dup.json: scenes[1]: the same scene as scenes[0] (\"a\" and \"b\")");
    EXPECT_FALSE(fs::exists(path("r.db")));
}

/// A program that registers its own structure (toy_list) and calls rcb::cli::main
/// (tests/cli_user_main.cpp), run as a user runs it.
Outcome run_user(const std::string& args) { return test::run_shell(std::string(RCB_CLI_USER_BINARY) + " " + args); }

TEST_F(Cli, AProgramLinkingTheCliGivesTheExecutablesErrors) {
    // The same bad input, the same one line and exit 2; only the list of known structures also
    // names the program's own.
    write("unknown.json", R"({"frames": 2, "rays_per_frame": 10, "scenes": [{"preset": "uni-s"}],
        "structures": [{"name": "bf"}, {"name": "sweepx"}]})");
    const Outcome mine = run_user("run " + path("unknown.json") + " --db " + path("r.db"));
    const Outcome rcbench = run("run " + path("unknown.json") + " --db " + path("r.db"));
    expect_bad_input(mine, "structures[1].name: unknown structure 'sweepx' (known: bf, ");
    expect_bad_input(rcbench, "structures[1].name: unknown structure 'sweepx' (known: bf, ");
    std::string expected = rcbench.err;
    expected.insert(expected.rfind(')'), ", toy_list");
    EXPECT_EQ(mine.err, expected);
    EXPECT_FALSE(fs::exists(path("r.db")));
    for (const std::string& args :
         {std::string("nosuch"), std::string("run"), std::string("history --last 0 x.db"), "fit " + path("none.db")}) {
        const Outcome a = run_user(args), b = run(args);
        EXPECT_EQ(a.code, 2) << args;
        EXPECT_EQ(a.err, b.err) << args;
    }
}

TEST_F(Cli, AProgramLinkingTheCliRunsItsStructureAndItsRunsStayApart) {
    write("mine.json", R"({"name": "mine", "frames": 3, "rays_per_frame": 50,
        "scenes": [{"generator": "uniform", "objects": 150}], "structures": [{"name": "toy_list"}, {"name": "bf"}]})");
    const Outcome ran = run_user("run " + path("mine.json") + " --db " + path("r.db"));
    ASSERT_EQ(ran.code, 0) << ran.err;
    EXPECT_NE(ran.out.find("toy_list"), std::string::npos) << ran.out;  // in the run's table
    // rcbench itself does not know the program's structure.
    expect_bad_input(run("run " + path("mine.json") + " --db " + path("r.db")),
                     "structures[0].name: unknown structure 'toy_list'");
    write("theirs.json", R"({"name": "theirs", "frames": 3, "rays_per_frame": 50,
        "scenes": [{"generator": "uniform", "objects": 150}], "structures": [{"name": "bf"}]})");
    ASSERT_EQ(run("run " + path("theirs.json") + " --db " + path("r.db")).code, 0);
    // Each run names its program: the executable's name and a build id of 40 hex digits.
    const Outcome runs =
        run("query --csv " + path("r.db") + " \"SELECT id, binary, length(binary_id) FROM run ORDER BY id\"");
    ASSERT_EQ(runs.code, 0) << runs.err;
    EXPECT_EQ(runs.out, "id,binary,length(binary_id)\n1,rcb_cli_user,40\n2,rcbench,40\n");
    // compare says when its sides come from two programs; the rows are what both measured.
    const Outcome c = run_user("compare " + path("r.db") + " --baseline 1 --candidate 2");
    ASSERT_EQ(c.code, 0) << c.err;
    EXPECT_EQ(c.out.rfind("Baseline by rcb_cli_user, candidate by rcbench: the rows are the configurations both "
                          "measured.\n",
                          0),
              0u)
        << c.out;
    EXPECT_EQ(c.out.find("toy_list"), std::string::npos) << c.out;
    const Outcome h = run_user("history " + path("r.db"));
    ASSERT_EQ(h.code, 0) << h.err;
    EXPECT_NE(h.out.find("rcb_cli_user"), std::string::npos) << h.out;  // the binary column
    const Outcome only = run_user("history " + path("r.db") + " --binary rcb_cli_user --structure toy_list");
    ASSERT_EQ(only.code, 0) << only.err;
    EXPECT_NE(only.out.find("1 series over 1 runs"), std::string::npos) << only.out;
    // The fit and the report take the program's structure as one of rcbench's.
    const Outcome fit = run_user("fit " + path("r.db") + " --run 1");
    ASSERT_EQ(fit.code, 0) << fit.err;
    EXPECT_NE(fit.out.find("toy_list"), std::string::npos) << fit.out;
    const Outcome report = run_user("report " + path("r.db") + " --run 1 -o " + path("report.html"));
    ASSERT_EQ(report.code, 0) << report.err;
    const std::string html = bytes_of(path("report.html"));
    EXPECT_NE(html.find("toy_list"), std::string::npos);
    EXPECT_NE(html.find("by rcb_cli_user (build "), std::string::npos);
}

TEST_F(Cli, AProgramLinkingTheCliTunesAndAdvisesItsStructureOverItsParamSpecs) {
    write("tune.json", R"({"name": "toy", "structures": ["toy_list"], "mode": "measured", "budget": 3,
        "frames": 3, "warmup_frames": 1, "rays_per_frame": 50, "repetitions": 1,
        "space": {"toy_list": {"block": [2, 8, 32]}},
        "categories": [{"name": "small", "scenes": [{"generator": "uniform", "objects": 150}]}]})");
    const Outcome tuned = run_user("tune " + path("tune.json") + " --db " + path("t.db") + " --out-dir " + path("out"));
    ASSERT_EQ(tuned.code, 0) << tuned.err;
    const auto tuning = nlohmann::json::parse(bytes_of(path("out/tuning-toy.json")));
    EXPECT_NE(tuning.dump().find("toy_list"), std::string::npos);
    ASSERT_EQ(run("scene gen --preset uni-s --frames 3 --rays 50 -o " + path("s.rcbscene")).code, 0);
    const Outcome advice = run_user("advise " + path("s.rcbscene") + " --tuning " + path("out/tuning-toy.json") +
                                    " --method category --json");
    ASSERT_EQ(advice.code, 0) << advice.err;
    EXPECT_NE(advice.out.find("toy_list"), std::string::npos) << advice.out;
    // rcbench itself cannot tune what it does not know: the tuning file is refused in one line.
    expect_bad_input(run("tune " + path("tune.json") + " --db " + path("t2.db") + " --out-dir " + path("out2")),
                     "unknown structure 'toy_list'");
}

TEST_F(Cli, CompareEndsWithThePerCellDifferenceBetweenTheTwoRuns) {
    write("e.json", R"({"name": "twice", "frames": 3, "rays_per_frame": 100,
        "scenes": [{"generator": "uniform", "objects": 200}, {"generator": "irregular", "objects": 200}],
        "structures": [{"name": "bf"}, {"name": "ug"}]})");
    ASSERT_EQ(run("run " + path("e.json") + " --db " + path("r.db")).code, 0);
    ASSERT_EQ(run("run " + path("e.json") + " --db " + path("r.db") + " --new-run").code, 0);
    const Outcome c = run("compare " + path("r.db") + " --baseline 1 --candidate 2 --metric both");
    ASSERT_EQ(c.code, 0) << c.err;
    // 2 scenes x 2 configurations, each metric: the spread between two runs, as the docs report it.
    EXPECT_NE(c.out.find("raycast: per-cell difference |candidate - baseline| / mean over 4 cells: p50 "),
              std::string::npos)
        << c.out;
    EXPECT_NE(c.out.find("update: per-cell difference |candidate - baseline| / mean over 4 cells: p50 "),
              std::string::npos)
        << c.out;
}

}  // namespace
