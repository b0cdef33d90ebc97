// The pipeline after reading (riemesh/vdb/pipeline.h), as vdb2mesh and the Python module call it: a
// small noisy ball phantom becomes one closed genus-0 mesh; the stages are reported in order and each
// can interrupt; bad options and isovalues are refused naming vdb2mesh's flag; the statistics document
// holds every section.
#include "riemesh/vdb/pipeline.h"
#include "riemesh/vdb/volume.h"
#include "riemesh/vdb/volume_sources.h"

#include "mesh_invariants.h"

#include <map>
#include <doctest/doctest.h>

#include <filesystem>
#include <functional>
#include <string>
#include <unistd.h>
#include <vector>

using namespace riemesh;
using namespace riemesh::vdb;
namespace fs = std::filesystem;

namespace {

/// A 32^3 ball phantom (noise 0.2, seed 3) written once (removed at exit) and read afresh for each test.
Volume ballPhantom()
{
    static const struct File {
        std::string path = (fs::temp_directory_path() / ("riemesh_pipeline_test_" + std::to_string(::getpid()) + ".vdb")).string();
        File() { writePhantom("ball", path, 32, 0.2, 3); }
        ~File() { fs::remove(path); }
    } file;
    return Volume::read(file.path);
}

std::string refusal(const std::function<void(PipelineOptions&)>& change)
{
    PipelineOptions o;
    change(o);
    try {
        Volume v = ballPhantom();
        meshVolume(v, o);
    } catch (const PipelineInputError& e) {
        return e.what();
    }
    return "accepted";
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

} // namespace

TEST_CASE("pipeline: a noisy ball phantom becomes one closed, outward, genus-0 mesh with vdb2mesh's defaults")
{
    Volume volume = ballPhantom();
    const PipelineResult r = meshVolume(volume, PipelineOptions{});
    CHECK_MESH_OK(r.mesh);
    CHECK((r.stop == StopReason::Converged));
    CHECK(r.topology.components == 1);
    CHECK(r.topology.genus == 0);
    std::size_t live = 0;
    for (auto v : r.mesh.vertices()) live += !r.mesh.status(v).deleted();
    CHECK(r.topology.vertices == live);
    CHECK(r.selfIntersections == 0);
    CHECK(r.iso == 0.5); // a fog volume
    CHECK(r.objectBrighter);
    CHECK(r.metric.activeVoxels > 0);
    CHECK(volume.hasMetric()); // the volume keeps what the model fitted
    CHECK(r.seconds.metric > 0);
    CHECK(r.seconds.evolve == r.evolution.seconds);

    PipelineRecord record;
    record.input = "ball.vdb";
    record.totalSeconds = 1.5;
    const std::string json = pipelineStatsJson(r, record);
    for (const char* key : {"\"input\": \"ball.vdb\"", "\"output\": null", "\"image\": {", "\"parameters\": {", "\"metric\": {",
                            "\"iterations\": [", "\"summary\": {", "\"genus\": 0", "\"stop\": \"converged\"", "\"seconds\": 1.5"})
        CHECK_MESSAGE(contains(json, key), key);
    CHECK_FALSE(contains(json, "\"reference\""));
}

TEST_CASE("pipeline: stages are reported in order, then every iteration; each report can interrupt")
{
    std::vector<PipelineStage> stages;
    int iterations = 0;
    PipelineOptions o;
    o.progress = [&](PipelineStage stage, const IterationStats* s) {
        if (s) {
            CHECK((stage == PipelineStage::Evolve));
            CHECK(s->iteration == ++iterations);
        } else {
            stages.push_back(stage);
        }
        return true;
    };
    Volume volume = ballPhantom();
    const PipelineResult full = meshVolume(volume, o);
    CHECK(stages == std::vector<PipelineStage>{PipelineStage::Borders, PipelineStage::Metric, PipelineStage::Smooth,
                                               PipelineStage::Convert, PipelineStage::Evolve});
    CHECK(iterations == int(full.evolution.iterations.size()));

    for (PipelineStage stop : {PipelineStage::Borders, PipelineStage::Metric, PipelineStage::Convert, PipelineStage::Evolve}) {
        o.progress = [&](PipelineStage stage, const IterationStats* s) { return s || stage != stop; };
        Volume v = ballPhantom();
        const PipelineResult r = meshVolume(v, o);
        CHECK((r.stop == StopReason::Interrupted));
        CHECK(r.mesh.n_vertices() == 0);
        CHECK(r.evolution.iterations.empty());
    }
    o.progress = [&](PipelineStage, const IterationStats* s) { return !s || s->iteration < 5; };
    Volume v = ballPhantom();
    const PipelineResult r = meshVolume(v, o);
    CHECK((r.stop == StopReason::Interrupted));
    CHECK(r.evolution.iterations.size() == 5);
    CHECK(r.mesh.n_vertices() > 0);
}

TEST_CASE("pipeline: the Euclidean metric computes no metric and the document has no metric section")
{
    PipelineOptions o;
    o.riemannian = false;
    Volume volume = ballPhantom();
    const PipelineResult r = meshVolume(volume, o);
    CHECK(r.topology.genus == 0);
    CHECK_FALSE(volume.hasMetric());
    CHECK(r.metric.activeVoxels == 0);
    CHECK_FALSE(contains(pipelineStatsJson(r, {}), "\"metric\": {"));
}

TEST_CASE("pipeline: bad options, isovalues and a runaway mesh are PipelineInputErrors naming vdb2mesh's flag")
{
    CHECK(contains(refusal([](PipelineOptions& o) { o.delta = 0; }), "--delta: must be > 0 (got 0)"));
    CHECK(contains(refusal([](PipelineOptions& o) { o.zeta = 1.5; }), "--zeta: must be >= 2"));
    CHECK(contains(refusal([](PipelineOptions& o) { o.muMax = 0.5; }), "--mu-max: must be in [1, 10000] (got 0.5)"));
    CHECK(contains(refusal([](PipelineOptions& o) { o.sigma = -1; }), "--sigma"));
    CHECK(contains(refusal([](PipelineOptions& o) { o.tangentialGain = 0; }), "--edge-gain"));
    CHECK(contains(refusal([](PipelineOptions& o) { o.smooth = -1; }), "--smooth"));
    CHECK(contains(refusal([](PipelineOptions& o) { o.maxIterations = 0; }), "--max-iterations"));
    CHECK(contains(refusal([](PipelineOptions& o) { o.downsample = 65; }), "--downsample"));
    CHECK(contains(refusal([](PipelineOptions& o) { o.iso = 7; }),
                   "--iso 7 is outside the values of image 'density'"));
    CHECK(contains(refusal([](PipelineOptions& o) { o.maxVertices = 100; }),
                   "the mesh grew past the vertex cap of 100 vertices (--max-vertices)"));
    CHECK(refusal([](PipelineOptions& o) { o.iso = 0.4; }) == "accepted");

    ImageInfo unknown;
    unknown.gridName = "t1";
    unknown.gridClass = "unknown";
    unknown.minValue = 0;
    unknown.maxValue = 100;
    try {
        pipelineIso(unknown, std::nullopt, "head.nii");
        FAIL("accepted an image of unknown class without an isovalue");
    } catch (const PipelineInputError& e) {
        CHECK(std::string(e.what()) == "'head.nii': image 't1' is neither a fog volume nor a level set: give --iso (its "
                                       "values range from 0 to 100)");
    }
    CHECK(pipelineIso(unknown, 40.0, "head.nii") == std::pair<double, bool>(40.0, true));
    unknown.gridClass = "levelset";
    unknown.minValue = -3;
    CHECK(pipelineIso(unknown, std::nullopt, "") == std::pair<double, bool>(0.0, false));
}

TEST_CASE("pipeline: --init specs parse to spheres or a mesh; bad ones name --init")
{
    CHECK(parseInitialSurface("box").kind == InitialSurface::Kind::Box);
    const InitialSurface s = parseInitialSurface("sphere:1,2,3,4;5,6,7,0.5");
    CHECK(s.kind == InitialSurface::Kind::Spheres);
    REQUIRE(s.spheres.size() == 2);
    CHECK(s.spheres[1].second == 0.5);
    CHECK(s.spec == "sphere:1,2,3,4;5,6,7,0.5");
    CHECK_THROWS_WITH_AS(parseInitialSurface("cone"), doctest::Contains("--init: 'cone' is not box"), PipelineInputError);
    CHECK_THROWS_WITH_AS(parseInitialSurface("sphere:1,2,3"), doctest::Contains("is not X,Y,Z,R"), PipelineInputError);
    CHECK_THROWS_WITH_AS(parseInitialSurface("sphere:1,2,3,-1"), doctest::Contains("radius must be > 0"), PipelineInputError);
    CHECK_THROWS_WITH_AS(parseInitialSurface("mesh:/no/such.ply"), doctest::Contains("--init mesh: "), PipelineInputError);
}

TEST_CASE("pipeline: a noisy 3-voxel plate converges as one piece, without merging and cutting through itself")
{
    // The plate's two faces are closer than the collision radius. A merge across it punches a hole
    // that a later merge of the hole's walls fills again, and a tunnel cut through its thickness
    // does the same: at noise 0.8 (seed 1) this ran to the 3,000-iteration cap ending with genus 1.
    // Pairs and necks with the object between them are kept apart instead (evolution.cpp).
    // Not checked: the genus. At noise 0.8 the rim still lets a few merges through (the image
    // between the pair reads background near the rim): genus 0 on 5 of seeds 1-12 before the
    // regularity change of the 300^3 churn, 4 of 12 after it (seed 1: genus 2). Issue 16 (thin
    // rims) is open for it; at noise 0.5 seeds 1-9 all end genus 0. Seed 2 had no merge or cut;
    // since the metric saturates below the faces' contrast (edges and corners refined as much as
    // faces, 3902536) seeds 2 and 7 have one merge through the plate that a cut takes back, the
    // other seven none (the sanitizers' build, whose floating point differs: seed 2 two of each).
    // What holds is that each merge is cut back, a handful at most (hundreds before).
    auto run = [](double noise, int seed) {
        Volume volume = phantomVolume("thin-plate", 100, noise, std::uint64_t(seed));
        return meshVolume(volume, PipelineOptions{});
    };
    const PipelineResult r = run(0.8, 1);
    CHECK_MESH_OK(r.mesh);
    CHECK((r.stop == StopReason::Converged));
    CHECK(r.topology.components == 1);
    CHECK(r.evolution.iterations.size() < 400);
    CHECK(r.evolution.merges + r.evolution.cuts <= 30); // 12 now; hundreds before
    const PipelineResult plain = run(0.5, 2);
    CHECK_MESH_OK(plain.mesh);
    CHECK((plain.stop == StopReason::Converged));
    CHECK(plain.topology.components == 1);
    CHECK(plain.topology.genus == 0);
    CHECK(plain.evolution.merges == plain.evolution.cuts); // each merge through the plate cut back
    CHECK(plain.evolution.merges + plain.evolution.cuts <= 8);
}

TEST_CASE("pipeline: with the guarantee, the noisy plate's merges are not repeated next to a fresh cut")
{
    // --intersection-free on the plate (noise 0.5, seed 2): a merge through the plate was cut back,
    // then merged again beside the cut; the run ended with genus 1 (88 iterations). A collision
    // pair next to a fresh cut is now held apart (Evolution::holdTopology): genus 0, 69 iterations.
    Volume volume = phantomVolume("thin-plate", 100, 0.5, 2);
    PipelineOptions o;
    o.intersectionFree = true;
    const PipelineResult r = meshVolume(volume, o);
    CHECK_MESH_OK(r.mesh);
    CHECK((r.stop == StopReason::Converged));
    CHECK(r.topology.components == 1);
    CHECK(r.topology.genus == 0);
    CHECK(r.selfIntersections == 0);
}

TEST_CASE("pipeline: with the guarantee, vertices held back by it do not keep a level from converging")
{
    // --intersection-free on the torus (noise 0.5, seed 1): the coarse level ran to its 300-iteration
    // cap (360 iterations in all, against 85 without the guarantee), because the vertices whose steps
    // the collision check shortened still counted as travelling (their drift held the displacement
    // integration meant, not the one they made). Now 18 + 85 iterations.
    Volume volume = phantomVolume("torus", 100, 0.5, 1);
    PipelineOptions o;
    o.intersectionFree = true;
    const PipelineResult r = meshVolume(volume, o);
    CHECK_MESH_OK(r.mesh);
    CHECK((r.stop == StopReason::Converged));
    CHECK(r.topology.components == 1);
    CHECK(r.topology.genus == 1);
    CHECK(r.selfIntersections == 0);
    std::map<int, int> perLevel;
    for (const auto& it : r.evolution.iterations) ++perLevel[it.level];
    for (const auto& entry : perLevel) { // (no structured binding: clang 14 cannot capture one in INFO)
        const int level = entry.first, iterations = entry.second;
        INFO("level " << level << ": " << iterations << " iterations");
        CHECK(iterations < 150);
    }
}

TEST_CASE("pipeline: the phantom at noise 1 stays one closed surface of genus 0")
{
    // The noise sweep's hardest level. A metric that saturated at a fixed fraction of the faces'
    // contrast (0.4, 3902536) turned into a step where the noise threshold came near that point, and
    // the phantom broke into 4 components here; saturating part of the way from the threshold
    // (metric_grid.h, referenceFraction) keeps it whole.
    Volume volume = phantomVolume("cube-cavity", 100, 1.0, 1);
    const PipelineResult r = meshVolume(volume, PipelineOptions{});
    CHECK_MESH_OK(r.mesh);
    CHECK((r.stop == StopReason::Converged));
    CHECK(r.topology.components == 1);
    CHECK(r.topology.genus == 0);
}

TEST_CASE("pipeline: a small noisy phantom at a fine delta keeps its one surface through the coarse level")
{
    // The cavity phantom at 40^3, noise 0.75, delta 1.2 voxels: one coarse level. When the coarse
    // image grew the blocks' maxima by a whole block, every blob of noise grew as much and the
    // coarse surface wrapped them, merged and cut through them, and turned inside out: seeds 2, 7
    // and 10 ended with 15, 0 and 0 vertices (7 of seeds 1-12 lost it so). Grown by half a block
    // (one cell of the finer level), all three keep the phantom's surface.
    for (int seed : {2, 7, 10}) {
        CAPTURE(seed);
        Volume volume = phantomVolume("cube-cavity", 40, 0.75, std::uint64_t(seed));
        PipelineOptions o;
        o.delta = 1.2;
        const PipelineResult r = meshVolume(volume, o);
        CHECK(r.levels == 1); // the coarse level was used
        CHECK_MESH_OK(r.mesh);
        CHECK((r.stop == StopReason::Converged));
        CHECK(r.topology.components == 1);
        CHECK(r.topology.genus == 0);
        CHECK(r.topology.vertices > 1000); // about 1,400: the whole cube, not a speck
    }
}
