// The rcbench binary as a user runs it: exit codes, one-line errors, outputs.
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sys/wait.h>

#include <nlohmann/json.hpp>

namespace {

namespace fs = std::filesystem;

struct Outcome {
    int code = -1;
    std::string out;  // stdout
    std::string err;  // stderr
};

class Cli : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("rcb_cli_" + std::to_string(::getpid()) + "_" +
                                            ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::create_directories(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }

    Outcome run(const std::string& args) {
        const std::string err_file = (dir_ / "stderr.txt").string();
        const std::string cmd = std::string(RCBENCH_BINARY) + " " + args + " 2>" + err_file;
        Outcome r;
        FILE* pipe = popen(cmd.c_str(), "r");
        std::array<char, 4096> buf;
        std::size_t n;
        while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.out.append(buf.data(), n);
        const int status = pclose(pipe);
        r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        std::ifstream e(err_file);
        r.err.assign(std::istreambuf_iterator<char>(e), {});
        return r;
    }
    std::string path(const std::string& name) const { return (dir_ / name).string(); }
    void write(const std::string& name, const std::string& text) const { std::ofstream(path(name)) << text; }

    fs::path dir_;
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

TEST_F(Cli, BadInputIsOneLineAndExitTwo) {
    const std::string scene = path("s.rcbscene");
    ASSERT_EQ(run("scene gen --preset uni-s --frames 1 -o " + scene).code, 0);
    expect_bad_input(run("simulate --scene " + scene + " --structure kdtree"), "unknown structure 'kdtree'");
    expect_bad_input(run("simulate --scene " + path("missing.rcbscene") + " --structure bf"), "missing.rcbscene: cannot open");
    expect_bad_input(run("simulate --scene " + scene + " --structure bf --param depth=3"), "--param.depth: unknown parameter of bf");
    expect_bad_input(run("scene gen --preset uni-xxl -o " + path("x")), "--preset: uni-xxl not in {uni-s,");
    expect_bad_input(run("scene gen --kind cubes --objects 10 -o " + path("x")), "--kind: cubes not in {uniform,irregular,stadium,");
    expect_bad_input(run("scene gen --preset uni-s --ray-mix sideways -o " + path("x")), "unknown mode 'sideways'");
    expect_bad_input(run("scene gen --preset uni-s --frames abc -o " + path("x")), "--frames");
    expect_bad_input(run("simulate --structure bf"), "--scene is required");
    write("corrupt.rcbscene", "RCBSCENE garbage");
    expect_bad_input(run("scene info " + path("corrupt.rcbscene")), "corrupt.rcbscene");
    write("rays.csv", "0,0,0,1,1,nan\n");
    expect_bad_input(run("cast --scene " + scene + " --rays " + path("rays.csv") + " --structure bf"), "rays.csv:1: non-finite coordinate");
    write("boxes.csv", "1,0,0,0,1,1,1\n1,0,0,0,1,1,1\n");
    expect_bad_input(run("scene import " + path("boxes.csv") + " -o " + path("y")), "boxes.csv:2: duplicate uid 1");
}

TEST_F(Cli, RunQueryCompareRejectBadInputInOneLine) {
    write("bad.json", R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf", "params": {"x": 1}}]})");
    expect_bad_input(run("run " + path("bad.json") + " --db " + path("r.db")), "bad.json: structures[0].params.x: unknown parameter of bf");
    EXPECT_FALSE(fs::exists(path("r.db")));  // nothing written for an invalid file
    write("ok.json", R"({"frames": 2, "rays_per_frame": 10, "scenes": [{"preset": "uni-s"}], "structures": [{"name": "bf"}]})");
    expect_bad_input(run("run " + path("ok.json") + " --shard 0/3 --db " + path("r.db")), "--shard 0/3: expected K/N");
    expect_bad_input(run("run " + path("missing.json")), "missing.json: cannot open");
    ASSERT_EQ(run("run " + path("ok.json") + " --db " + path("r.db")).code, 0);
    expect_bad_input(run("query " + path("r.db") + " \"DELETE FROM cell\""), "only read-only statements");
    expect_bad_input(run("query " + path("r.db") + " \"SELECT nope FROM cell\""), "query: no such column: nope");
    expect_bad_input(run("query " + path("none.db") + " \"SELECT 1\""), "none.db: no such results database");
    expect_bad_input(run("compare " + path("r.db") + " --baseline 1 --candidate 7"), "no run matches '7'");
    const Outcome csv = run("query --csv " + path("r.db") + " \"SELECT structure, count(*) AS cells FROM cell_summary GROUP BY 1\"");
    EXPECT_EQ(csv.out, "structure,cells\nbf,1\n");
}

TEST_F(Cli, HelpTellsTheSubcommands) {
    const Outcome help = run("--help");
    EXPECT_EQ(help.code, 0);
    for (const char* sub : {"scene", "simulate", "cast", "structures", "run", "query", "compare", "merge"}) EXPECT_NE(help.out.find(sub), std::string::npos) << sub;
    const Outcome structures = run("structures --json");
    EXPECT_EQ(structures.code, 0);
    EXPECT_EQ(nlohmann::json::parse(structures.out)[0]["name"], "bf");
}

}  // namespace
