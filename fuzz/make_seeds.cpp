// fuzz_make_seeds OUTDIR: the seed corpora of the fuzz targets, made with riemesh's own writers
// (phantoms, NanoVDB export, mesh writers; nifticlib for NIfTI), so that no binary file is
// committed. One folder per target: OUTDIR/{vdb_read,nvdb_read,nifti_read,mesh_read,vdb2mesh_args}.
#include "riemesh/mesh_io.h"
#include "riemesh/primitives.h"
#include "riemesh/vdb/io.h"
#include "riemesh/vdb/metric_grid.h"
#include "riemesh/vdb/nano.h"
#include "riemesh/vdb/phantom.h"

#include "isolated_read.h"

#include <nifti2_io.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace riemesh;

namespace {

std::string slurp(const fs::path& p)
{
    std::ifstream in(p, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

void put(const fs::path& p, const std::string& bytes)
{
    std::ofstream(p, std::ios::binary) << bytes;
}

/// A small NIfTI image of `datatype` (values a ramp with a bright ball), written by nifticlib.
void writeNifti(const fs::path& path, int datatype, int nx, int ny, int nz)
{
    const int64_t dims[8] = {3, nx, ny, nz, 1, 1, 1, 1};
    nifti_image* nim = nifti_make_new_nim(dims, datatype, 1);
    if (!nim) throw std::runtime_error("nifti_make_new_nim failed");
    for (int64_t i = 0; i < nim->nvox; ++i) {
        const double v = (i % 7) * 10.0;
        if (datatype == NIFTI_TYPE_FLOAT32) static_cast<float*>(nim->data)[i] = float(v);
        else if (datatype == NIFTI_TYPE_INT16) static_cast<int16_t*>(nim->data)[i] = int16_t(v);
        else static_cast<uint8_t*>(nim->data)[i] = uint8_t(v);
    }
    nim->qform_code = NIFTI_XFORM_SCANNER_ANAT;
    nim->quatern_b = 0.1f;
    nim->dx = 1.5f;
    if (nifti_set_filenames(nim, path.c_str(), 0, 1) != 0) throw std::runtime_error("nifti_set_filenames failed");
    nifti_image_write(nim);
    nifti_image_free(nim);
}

} // namespace

int main(int argc, char** argv)
{
    if (argc != 2) {
        std::fprintf(stderr, "usage: fuzz_make_seeds OUTDIR\n");
        return 1;
    }
    try {
        const fs::path out(argv[1]);
        for (const char* t : {"vdb_read", "vdb_answer", "nvdb_read", "nifti_read", "mesh_read", "vdb2mesh_args"})
            fs::create_directories(out / t);

        // .vdb: small phantoms (fog density + level set sdf), and a double grid.
        vdb::PhantomOptions o;
        o.size = 16;
        o.noise = 0.1;
        const auto ball = vdb::makePhantom(vdb::PhantomShape::Ball, o);
        vdb::writeVdb((out / "vdb_read/ball.vdb").string(), {ball.density, ball.sdf});
        const auto torus = vdb::makePhantom(vdb::PhantomShape::Torus, o);
        vdb::writeVdb((out / "vdb_read/torus_sdf.vdb").string(), {torus.sdf});
        auto d = openvdb::DoubleGrid::create(0.0);
        d->setName("double");
        for (int i = 0; i < 4; ++i) d->tree().setValue(openvdb::Coord(i, i, 2 * i), 1.0 + i);
        vdb::writeVdb((out / "vdb_read/double.vdb").string(), {d});
        // The isolated reader's answers for them (vdb/src/isolated_read.h).
        std::ofstream(out / "vdb_answer/ball_density.bin", std::ios::binary) << vdb::detail::childAnswerOf(*ball.density);
        std::ofstream(out / "vdb_answer/torus_sdf.bin", std::ios::binary) << vdb::detail::childAnswerOf(*torus.sdf);
        std::ofstream(out / "vdb_answer/double.bin", std::ios::binary) << vdb::detail::childAnswerOf(*d);

        // .nvdb: the image alone, and with its metric (as vdb2mesh --export-nvdb writes it).
        vdb::writeNvdb((out / "nvdb_read/ball.nvdb").string(), *ball.density);
        const auto metric = vdb::computeMetric(*ball.density);
        vdb::writeNvdb((out / "nvdb_read/ball_metric.nvdb").string(), *ball.density, metric.diag.get(),
                       metric.off.get());

        // NIfTI: uint8, int16 with a qform, float32 gzipped.
        writeNifti(out / "nifti_read/u8.nii", NIFTI_TYPE_UINT8, 6, 5, 4);
        writeNifti(out / "nifti_read/i16.nii", NIFTI_TYPE_INT16, 4, 4, 4);
        writeNifti(out / "nifti_read/f32.nii.gz", NIFTI_TYPE_FLOAT32, 5, 4, 3);

        // Meshes: an icosphere and a torus in every format, behind the target's format byte
        // (0 OBJ, 1 PLY, 2 OFF, 3 STL).
        const Mesh sphere = makeIcosphere(Vec3(0, 0, 0), 1.0, 1);
        const Mesh ring = makeTorus(Vec3(0, 0, 0), 2.0, 0.7, 8, 5);
        struct Kind {
            const char* ext;
            MeshFormat format;
            char selector;
        };
        const Kind kinds[] = {{".obj", MeshFormat::Obj, 0}, {".ply", MeshFormat::Ply, 1},
                              {".ply", MeshFormat::PlyAscii, 1}, {".off", MeshFormat::Off, 2},
                              {".stl", MeshFormat::Stl, 3}};
        int n = 0;
        for (const Mesh* mesh : {&sphere, &ring}) {
            for (const auto& k : kinds) {
                const fs::path tmp = out / (std::string("tmp") + k.ext);
                writeMesh(tmp.string(), *mesh, k.format, "seed");
                put(out / "mesh_read" / ("mesh" + std::to_string(n++)), std::string(1, k.selector) + slurp(tmp));
                fs::remove(tmp);
            }
        }
        // An ascii STL by hand (the writer writes binary STL).
        put(out / "mesh_read/ascii.stl", std::string(1, 3) +
                "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 0 1 0\n"
                "  endloop\n endfacet\nendsolid t\n");

        // vdb2mesh command lines, NUL-separated.
        const std::vector<std::string> lines = {
            "in.vdb|out.ply|--delta|2|--zeta|3|--mu-max|4",
            "in.nii.gz|/tmp/out.obj|--iso|40|--metric|euclidean|--threads|2|-q",
            "in.nvdb|out.stl|--init|sphere:1,2,3,4;5,6,7,1.5|--max-iterations|10",
            "in.vdb|out.vdb|--max-memory|1.5G|--max-vertices|1000|--smooth|0",
            "in.vdb|out.off|--grid|density|--sigma|1|--rho|2|--init|mesh:x.obj|--stats|s.json",
            "--help"};
        for (std::size_t i = 0; i < lines.size(); ++i) {
            std::string bytes = lines[i];
            for (char& c : bytes)
                if (c == '|') c = '\0';
            put(out / "vdb2mesh_args" / ("args" + std::to_string(i)), bytes);
        }
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "fuzz_make_seeds: error: %s\n", e.what());
        return 1;
    }
}
