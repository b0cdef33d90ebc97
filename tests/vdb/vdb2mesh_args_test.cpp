// vdb2mesh's command line parsed directly (vdb/apps/vdb2mesh_args.h), as the fuzzer calls it:
// defaults, every flag's value, --help, and refusals as BadInput naming the flag.
#include "cli.h"
#include "vdb2mesh_args.h"

#include <doctest/doctest.h>

#include <string>
#include <vector>

using namespace riemesh::apps;

namespace {

Vdb2MeshArgs parse(std::vector<std::string> words)
{
    words.insert(words.begin(), "vdb2mesh");
    std::vector<const char*> argv;
    for (const auto& w : words) argv.push_back(w.c_str());
    return parseVdb2MeshArgs(int(argv.size()), argv.data());
}

std::string refusal(const std::vector<std::string>& words)
{
    try {
        parse(words);
    } catch (const BadInput& e) {
        return e.what();
    }
    return "accepted";
}

} // namespace

TEST_CASE("vdb2mesh args: defaults, then every flag's value lands in its field")
{
    const Vdb2MeshArgs d = parse({"in.vdb", "out.ply"});
    CHECK(d.input == "in.vdb");
    CHECK(d.output == "out.ply");
    CHECK(d.delta == kDelta);
    CHECK(d.maxVertices == kMaxVertices);
    CHECK(d.maxMemory == 0);
    CHECK_FALSE(d.iso);
    CHECK_FALSE(d.help);
    CHECK(d.sharpen);
    CHECK_FALSE(d.faceSamples);

    const Vdb2MeshArgs a = parse({"--delta", "2", "in.nii.gz", "--zeta", "3", "--mu-max", "4", "--iso", "40",
                                  "--metric", "euclidean", "--threads", "2", "--max-iterations", "7",
                                  "--max-vertices", "1000", "--max-memory", "1.5G", "--smooth", "0", "-q",
                                  "out.obj", "--init", "sphere:1,2,3,4", "--no-sharpen", "--face-samples"});
    CHECK(a.input == "in.nii.gz");
    CHECK(a.output == "out.obj");
    CHECK(a.delta == 2);
    CHECK(a.zeta == 3);
    CHECK(a.muMax == 4);
    CHECK(*a.iso == 40);
    CHECK_FALSE(a.riemannian);
    CHECK(a.threads == 2);
    CHECK(a.maxIterations == 7);
    CHECK(a.maxVertices == 1000);
    CHECK(a.maxMemory == std::uint64_t(1.5 * 1024 * 1024 * 1024));
    CHECK(a.smooth == 0);
    CHECK(a.quiet);
    CHECK(parseSpheres(a.init.substr(7)).size() == 1);
    CHECK_FALSE(a.sharpen);
    CHECK(a.faceSamples);
}

TEST_CASE("vdb2mesh args: --help stops parsing (later words are not checked)")
{
    CHECK(parse({"--help", "--delta", "-1"}).help);
    CHECK(parse({"in.vdb", "-h"}).help);
}

TEST_CASE("vdb2mesh args: bad values are BadInput naming the flag")
{
    const std::pair<std::vector<std::string>, std::string> cases[] = {
        {{"a.vdb", "b.ply", "--delta", "-1"}, "--delta: must be > 0"},
        {{"a.vdb", "b.ply", "--zeta", "0.5"}, "--zeta"},
        {{"a.vdb", "b.ply", "--iso", "banana"}, "--iso: 'banana' is not a number"},
        {{"a.vdb", "b.ply", "--iso", "nan"}, "--iso: 'nan' is not a number"},
        {{"a.vdb", "b.ply", "--mu-max", "0"}, "--mu-max"},
        {{"a.vdb", "b.ply", "--threads", "-3"}, "--threads"},
        {{"a.vdb", "b.ply", "--max-iterations", "x"}, "--max-iterations: 'x' is not a number"},
        {{"a.vdb", "b.ply", "--max-iterations", "1e10"}, "--max-iterations"},
        {{"a.vdb", "b.ply", "--max-vertices", "3.5"}, "--max-vertices"},
        {{"a.vdb", "b.ply", "--max-memory", "-1G"}, "--max-memory"},
        {{"a.vdb", "b.ply", "--max-memory", "G"}, "--max-memory: '' is not a number"},
        {{"a.vdb", "b.ply", "--max-memory", "1e300T"}, "--max-memory"},
        {{"a.vdb", "b.ply", "--sigma"}, "--sigma: missing value"},
        {{"a.vdb", "b.ply", "--frobnicate"}, "unknown option '--frobnicate'"},
        {{"a.vdb"}, "expected INPUT and OUTPUT"},
        {{"a.vdb", "b.ply", "c.ply"}, "expected INPUT and OUTPUT"},
    };
    for (const auto& c : cases) { // no structured binding: INFO's lambda captures (C++20 only)
        const std::string message = refusal(c.first);
        INFO(c.first.back() << ": " << message);
        CHECK(message.find(c.second) != std::string::npos);
    }
}

TEST_CASE("vdb2mesh args: byte counts take K/M/G/T suffixes in powers of 1024")
{
    CHECK(parseByteCount("--max-memory", "1048576") == 1048576);
    CHECK(parseByteCount("--max-memory", "512m") == 512ull << 20);
    CHECK(parseByteCount("--max-memory", "2G") == 2ull << 30);
    CHECK(parseByteCount("--max-memory", "1T") == 1ull << 40);
    CHECK_THROWS_AS(parseByteCount("--max-memory", "1K"), BadInput); // below a megabyte
}
