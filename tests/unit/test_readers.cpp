// Field readers (npy, vti, legacy vtk, raw, split VDB components) and field preparation
// (NaN policy, crop, mask, resample). Fixtures are written from C++ here, so every byte is known.
#include <gtest/gtest.h>

#include "TempDirSuite.h"

#include "vdbexport/io/FieldInput.h"
#include "vdbexport/io/AtomicWrite.h"

#include <lic/util/Error.h>

#include <openvdb/openvdb.h>
#include <zlib.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <vector>


namespace fs = std::filesystem;
using namespace vdbexport;
using openvdb::Vec3d;
using openvdb::Vec3s;

namespace {

/// The test field: value at voxel (i,j,k) = (1 + i, 10 + j, 100 + k) — every voxel distinct
/// and non-zero, so any layout mix-up shows.
Vec3s expected(int i, int j, int k) { return Vec3s(1.0f + i, 10.0f + j, 100.0f + k); }

template<typename T>
void append(std::string& s, T v, bool big = false)
{
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if (big == (std::endian::native == std::endian::little))
        for (std::size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(b[i], b[sizeof(T) - 1 - i]);
    s.append(b, sizeof(T));
}

/// A .npy v1.0 file: shape text like "(4, 3, 2, 3)", data as given.
std::string npy(const std::string& descr, bool fortran, const std::string& shape, const std::string& data)
{
    std::string dict = "{'descr': '" + descr + "', 'fortran_order': " + (fortran ? "True" : "False") + ", 'shape': " + shape + ", }";
    while ((10 + dict.size() + 1) % 64 != 0) dict += ' ';
    dict += '\n';
    std::string s("\x93NUMPY\x01\x00", 8);
    append<uint16_t>(s, uint16_t(dict.size()));
    return s + dict + data;
}

/// Data of the test field with dims (X,Y,Z) in a given axis order. `layout`: "xyzc" = shape
/// (X,Y,Z,3) C order; "cxyz" = (3,X,Y,Z) C order; "xyzc-F" = (X,Y,Z,3) Fortran order.
template<typename T>
std::string fieldData(int X, int Y, int Z, const std::string& layout, bool big = false)
{
    std::string s;
    auto put = [&](int i, int j, int k, int c) { append<T>(s, T(expected(i, j, k)[c]), big); };
    if (layout == "xyzc") {
        for (int i = 0; i < X; ++i) for (int j = 0; j < Y; ++j) for (int k = 0; k < Z; ++k) for (int c = 0; c < 3; ++c) put(i, j, k, c);
    } else if (layout == "cxyz") {
        for (int c = 0; c < 3; ++c) for (int i = 0; i < X; ++i) for (int j = 0; j < Y; ++j) for (int k = 0; k < Z; ++k) put(i, j, k, c);
    } else { // Fortran (X,Y,Z,3): i fastest, c slowest; also VTK's x-fastest component-last-slowest is not this
        for (int c = 0; c < 3; ++c) for (int k = 0; k < Z; ++k) for (int j = 0; j < Y; ++j) for (int i = 0; i < X; ++i) put(i, j, k, c);
    }
    return s;
}

/// VTK order: x fastest, components interleaved.
template<typename T>
std::string vtkData(int X, int Y, int Z, bool big = false)
{
    std::string s;
    for (int k = 0; k < Z; ++k) for (int j = 0; j < Y; ++j) for (int i = 0; i < X; ++i) for (int c = 0; c < 3; ++c)
        append<T>(s, T(expected(i, j, k)[c]), big);
    return s;
}

void expectImage(const DenseImage& img, int X, int Y, int Z)
{
    ASSERT_EQ(img.dims[0], X);
    ASSERT_EQ(img.dims[1], Y);
    ASSERT_EQ(img.dims[2], Z);
    ASSERT_FALSE(img.arrays.empty());
    const auto& a = img.arrays.front();
    ASSERT_EQ(a.components, 3);
    ASSERT_EQ(a.data.size(), std::size_t(X) * Y * Z * 3);
    for (int k = 0; k < Z; ++k)
        for (int j = 0; j < Y; ++j)
            for (int i = 0; i < X; ++i)
                for (int c = 0; c < 3; ++c)
                    ASSERT_EQ(a.data[((std::size_t(k) * Y + j) * X + i) * 3 + c], expected(i, j, k)[c])
                        << "voxel (" << i << "," << j << "," << k << ") component " << c;
}

/// Expect `fn` to throw lic::InputError whose message contains every word.
void expectInputError(const std::function<void()>& fn, const std::vector<std::string>& words)
{
    try {
        fn();
        ADD_FAILURE() << "no exception";
    } catch (const lic::InputError& e) {
        const std::string msg = e.what();
        for (const auto& w : words) EXPECT_NE(msg.find(w), std::string::npos) << "message lacks '" << w << "': " << msg;
    }
}

std::string base64(const std::string& in)
{
    static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    std::size_t i = 0;
    for (; i + 2 < in.size(); i += 3) {
        const unsigned n = (unsigned char)in[i] << 16 | (unsigned char)in[i + 1] << 8 | (unsigned char)in[i + 2];
        out += t[n >> 18]; out += t[(n >> 12) & 63]; out += t[(n >> 6) & 63]; out += t[n & 63];
    }
    if (i + 1 == in.size()) {
        const unsigned n = (unsigned char)in[i] << 16;
        out += t[n >> 18]; out += t[(n >> 12) & 63]; out += "==";
    } else if (i + 2 == in.size()) {
        const unsigned n = (unsigned char)in[i] << 16 | (unsigned char)in[i + 1] << 8;
        out += t[n >> 18]; out += t[(n >> 12) & 63]; out += t[(n >> 6) & 63]; out += '=';
    }
    return out;
}

std::string vti(const std::string& header, const std::string& arrays, const std::string& extent = "0 3 0 2 0 1",
                const std::string& tail = "", const std::string& data = "PointData")
{
    return "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\" " + header
        + ">\n<ImageData WholeExtent=\"" + extent + "\" Origin=\"1 2 3\" Spacing=\"0.5 0.5 0.5\">\n<Piece Extent=\""
        + extent + "\">\n<" + data + " Vectors=\"velocity\">\n" + arrays + "</" + data + ">\n</Piece>\n</ImageData>\n" + tail
        + "</VTKFile>\n";
}

class TempDir : public lictest::TempDirTest
{
protected:
    std::string write(const std::string& name, const std::string& bytes)
    {
        const fs::path p = mDir / name;
        std::ofstream(p, std::ios::binary) << bytes;
        return p.string();
    }
};

} // namespace

// ---- npy ----------------------------------------------------------------------------------

TEST(Npy, XyzcFloat32COrder)
{
    expectImage(parseNpy(npy("<f4", false, "(4, 3, 2, 3)", fieldData<float>(4, 3, 2, "xyzc")), "t.npy"), 4, 3, 2);
}

TEST(Npy, CxyzFloat64)
{
    expectImage(parseNpy(npy("<f8", false, "(3, 4, 3, 2)", fieldData<double>(4, 3, 2, "cxyz")), "t.npy"), 4, 3, 2);
}

TEST(Npy, FortranOrder)
{
    expectImage(parseNpy(npy("<f4", true, "(4, 3, 2, 3)", fieldData<float>(4, 3, 2, "xyzc-F")), "t.npy"), 4, 3, 2);
}

TEST(Npy, BigEndian)
{
    expectImage(parseNpy(npy(">f8", false, "(4, 3, 2, 3)", fieldData<double>(4, 3, 2, "xyzc", true)), "t.npy"), 4, 3, 2);
}

TEST(Npy, ScalarArray)
{
    std::string d;
    for (int i = 0; i < 2 * 2 * 2; ++i) append<float>(d, float(i));
    const DenseImage img = parseNpy(npy("<f4", false, "(2, 2, 2)", d), "s.npy");
    ASSERT_EQ(img.arrays.size(), 1u);
    EXPECT_EQ(img.arrays[0].components, 1);
    // C order (X,Y,Z): element (i,j,k) = i*4 + j*2 + k; stored x fastest.
    EXPECT_EQ(img.arrays[0].data[1], 4.0f); // (1,0,0)
    EXPECT_EQ(img.arrays[0].data[2], 2.0f); // (0,1,0)
    EXPECT_EQ(img.arrays[0].data[4], 1.0f); // (0,0,1)
}

TEST(Npy, RefusesBadInput)
{
    const std::string good = fieldData<float>(4, 3, 2, "xyzc");
    expectInputError([&] { parseNpy("PK\x03\x04 not numpy at all", "a.npy"); }, {"a.npy", "not a NumPy"});
    expectInputError([&] { parseNpy(npy("<c8", false, "(4, 3, 2, 3)", good), "a.npy"); }, {"dtype", "<c8"});
    expectInputError([&] { parseNpy(npy("<f4", false, "(4, 6)", good), "a.npy"); }, {"shape", "(4, 6)"});
    expectInputError([&] { parseNpy(npy("<f4", false, "(4, 3, 2, 3)", good.substr(0, good.size() - 4)), "a.npy"); },
                     {"truncated"});
    expectInputError([&] { parseNpy(npy("<f4", false, "(4, 3, 2, 3)", good + "xxxx"), "a.npy"); }, {"exactly one array"});
    // Enormous declared dimensions: refused from the header alone (nothing allocated).
    expectInputError([&] { parseNpy(npy("<f4", false, "(100000, 100000, 100000, 3)", good), "a.npy"); },
                     {"too large"});
    expectInputError([&] { parseNpy(npy("<f4", false, "(0, 3, 2, 3)", ""), "a.npy"); }, {"at least 1"});
    std::string cut = npy("<f4", false, "(4, 3, 2, 3)", good);
    expectInputError([&] { parseNpy(cut.substr(0, 20), "a.npy"); }, {"cut short"});
}

TEST(Raw, ShapeAndDtype)
{
    expectImage(parseRaw(fieldData<float>(4, 3, 2, "xyzc"), {4, 3, 2}, "float32", "r.raw"), 4, 3, 2);
    expectImage(parseRaw(fieldData<double>(4, 3, 2, "xyzc", true), {4, 3, 2}, ">f8", "r.raw"), 4, 3, 2);
    expectInputError([&] { parseRaw(fieldData<float>(4, 3, 2, "xyzc"), {4, 3, 3}, "float32", "r.raw"); },
                     {"r.raw", "bytes", "--shape"});
    expectInputError([&] { parseRaw(fieldData<float>(4, 3, 2, "xyzc"), {4, 3, 2}, "int7", "r.raw"); }, {"dtype"});
}

// ---- vti ----------------------------------------------------------------------------------

TEST(Vti, AsciiPointData)
{
    std::string values;
    const std::string bin = vtkData<float>(4, 3, 2);
    for (std::size_t i = 0; i < bin.size(); i += 4) {
        float v;
        std::memcpy(&v, bin.data() + i, 4);
        values += std::to_string(v) + (i % 48 == 44 ? "\n" : " ");
    }
    const DenseImage img = parseVti(
        vti("", "<DataArray type=\"Float32\" Name=\"velocity\" NumberOfComponents=\"3\" format=\"ascii\">\n" + values
                    + "</DataArray>\n<DataArray type=\"Float64\" Name=\"temperature\" format=\"ascii\">"
                    + std::string(24 * 2, ' ') + "1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24</DataArray>\n"),
        "t.vti");
    expectImage(img, 4, 3, 2);
    EXPECT_EQ(img.origin, Vec3d(1, 2, 3));
    EXPECT_EQ(img.spacing, Vec3d(0.5));
    ASSERT_EQ(img.arrays.size(), 2u);
    EXPECT_EQ(img.arrays[1].name, "temperature");
    EXPECT_EQ(img.arrays[1].data[23], 24.0f);
}

TEST(Vti, Base64BinaryUInt32)
{
    const std::string data = vtkData<float>(4, 3, 2);
    std::string header;
    append<uint32_t>(header, uint32_t(data.size()));
    // VTK encodes the header and the data separately.
    const DenseImage img = parseVti(
        vti("header_type=\"UInt32\"", "<DataArray type=\"Float32\" Name=\"v\" NumberOfComponents=\"3\" format=\"binary\">\n"
                                          + base64(header) + base64(data) + "\n</DataArray>\n"),
        "t.vti");
    expectImage(img, 4, 3, 2);
}

TEST(Vti, ZlibCompressedUInt64)
{
    const std::string data = vtkData<double>(4, 3, 2);
    // Two blocks: 100 bytes and the rest.
    const std::size_t blockSize = 100;
    std::vector<std::string> blocks;
    for (std::size_t off = 0; off < data.size(); off += blockSize) {
        const std::string part = data.substr(off, blockSize);
        uLongf len = compressBound(uLong(part.size()));
        std::string z(len, '\0');
        ASSERT_EQ(compress(reinterpret_cast<Bytef*>(z.data()), &len, reinterpret_cast<const Bytef*>(part.data()), uLong(part.size())), Z_OK);
        blocks.push_back(z.substr(0, len));
    }
    std::string header;
    append<uint64_t>(header, blocks.size());
    append<uint64_t>(header, blockSize);
    append<uint64_t>(header, data.size() % blockSize);
    std::string body;
    for (const auto& b : blocks) {
        append<uint64_t>(header, b.size());
        body += b;
    }
    const DenseImage img = parseVti(
        vti("header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\"",
            "<DataArray type=\"Float64\" Name=\"velocity\" NumberOfComponents=\"3\" format=\"binary\">" + base64(header)
                + base64(body) + "</DataArray>\n"),
        "z.vti");
    expectImage(img, 4, 3, 2);
}

TEST(Vti, AppendedRawCellData)
{
    const std::string data = vtkData<float>(4, 3, 2);
    std::string block;
    append<uint32_t>(block, uint32_t(data.size()));
    block += data;
    const DenseImage img = parseVti(
        vti("header_type=\"UInt32\"", "<DataArray type=\"Float32\" Name=\"velocity\" NumberOfComponents=\"3\" format=\"appended\" offset=\"0\"/>\n",
            "0 4 0 3 0 2", "<AppendedData encoding=\"raw\">\n_" + block + "\n</AppendedData>\n", "CellData"),
        "c.vti");
    expectImage(img, 4, 3, 2);
    // Cell centres: origin + (i + ½)·spacing.
    EXPECT_EQ(img.origin, Vec3d(1.25, 2.25, 3.25));
}

TEST(Vti, RefusesBadInput)
{
    const std::string arr = "<DataArray type=\"Float32\" Name=\"velocity\" NumberOfComponents=\"3\" format=\"ascii\">1 2 3</DataArray>\n";
    expectInputError([&] { parseVti("hello", "a.vti"); }, {"a.vti", "not a VTK XML"});
    expectInputError([&] { parseVti(vti("", arr), "a.vti"); }, {"mismatched shape"});
    expectInputError([&] { parseVti(vti("", arr, "0 99999 0 99999 0 99999"), "a.vti"); }, {"too large"});
    std::string zeroSpacing = vti("", arr, "0 0 0 0 0 0");
    zeroSpacing.replace(zeroSpacing.find("Spacing=\"0.5 0.5 0.5\""), 21, "Spacing=\"0 1 1\"");
    expectInputError([&] { parseVti(zeroSpacing, "a.vti"); }, {"spacing", "not positive"});
    expectInputError([&] { parseVti(vti("", "<DataArray type=\"Float16\" Name=\"v\" format=\"ascii\">1</DataArray>", "0 0 0 0 0 0"), "a.vti"); },
                     {"Float16"});
    // A binary header declaring far more bytes than present.
    std::string header;
    append<uint32_t>(header, 0xFFFFFFF0u);
    expectInputError([&] {
        parseVti(vti("", "<DataArray type=\"Float32\" Name=\"velocity\" NumberOfComponents=\"3\" format=\"binary\">" + base64(header)
                             + base64("abcd") + "</DataArray>"), "a.vti");
    }, {"mismatched shape"});
}

// ---- legacy vtk ---------------------------------------------------------------------------

TEST(LegacyVtk, AsciiAndBinary)
{
    const std::string head = "# vtk DataFile Version 3.0\nfield\n";
    const std::string geo = "DATASET STRUCTURED_POINTS\nDIMENSIONS 4 3 2\nORIGIN 1 2 3\nSPACING 0.5 0.5 0.5\nPOINT_DATA 24\n";
    std::string ascii = head + "ASCII\n" + geo + "VECTORS velocity float\n";
    for (int k = 0; k < 2; ++k) for (int j = 0; j < 3; ++j) for (int i = 0; i < 4; ++i) {
        const Vec3s v = expected(i, j, k);
        ascii += std::to_string(v[0]) + " " + std::to_string(v[1]) + " " + std::to_string(v[2]) + "\n";
    }
    ascii += "SCALARS temperature float 1\nLOOKUP_TABLE default\n";
    for (int i = 0; i < 24; ++i) ascii += std::to_string(i) + " ";
    DenseImage img = parseLegacyVtk(ascii, "a.vtk");
    expectImage(img, 4, 3, 2);
    EXPECT_EQ(img.origin, Vec3d(1, 2, 3));
    ASSERT_EQ(img.arrays.size(), 2u);
    EXPECT_EQ(img.arrays[1].name, "temperature");

    const std::string bin = head + "BINARY\n" + geo + "VECTORS velocity double\n" + vtkData<double>(4, 3, 2, /*big=*/true) + "\n";
    expectImage(parseLegacyVtk(bin, "b.vtk"), 4, 3, 2);

    expectInputError([&] { parseLegacyVtk(head + "BINARY\n" + geo + "VECTORS velocity double\n" + "short", "b.vtk"); },
                     {"cut short"});
    expectInputError([&] { parseLegacyVtk(head + "ASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 100000 100000 100000\n", "h.vtk"); },
                     {"too large"});
    expectInputError([&] { parseLegacyVtk(head + "ASCII\nDATASET POLYDATA\n", "p.vtk"); }, {"STRUCTURED_POINTS"});
    // Found by fuzz_vti: a POINT_DATA count far beyond int64 was cast to an integer for the message.
    expectInputError([&] { parseLegacyVtk(head + "ASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 2 2\nPOINT_DATA 8.9e91\n", "n.vtk"); },
                     {"does not match DIMENSIONS"});
    expectInputError([&] { parseLegacyVtk("solid cube\n", "s.vtk"); }, {"not a legacy VTK"});
}

// ---- loadField: formats, transforms, preparation -------------------------------------------

TEST_F(TempDir, NpyWorldPositionFromVoxelSizeAndOrigin)
{
    FieldSpec spec;
    spec.path = write("f.npy", npy("<f4", false, "(4, 3, 2, 3)", fieldData<float>(4, 3, 2, "xyzc")));
    spec.voxelSize = 0.25;
    spec.origin = std::array<double, 3>{-1.0, 2.0, 5.0};
    const LoadedField f = loadField(spec);
    EXPECT_EQ(f.format, "npy");
    ASSERT_TRUE(f.velocity);
    EXPECT_EQ(f.velocity->activeVoxelCount(), 24u);
    // World position of voxel (i,j,k)'s centre = origin + (i,j,k)·voxel_size.
    const Vec3d w = f.velocity->indexToWorld(openvdb::Coord(3, 2, 1));
    EXPECT_NEAR(w[0], -1.0 + 3 * 0.25, 1e-12);
    EXPECT_NEAR(w[1], 2.0 + 2 * 0.25, 1e-12);
    EXPECT_NEAR(w[2], 5.0 + 1 * 0.25, 1e-12);
    EXPECT_EQ(f.velocity->tree().getValue(openvdb::Coord(3, 2, 1)), expected(3, 2, 1));
}

TEST_F(TempDir, VtiScalarsAndFormatOverride)
{
    const std::string data = vtkData<float>(4, 3, 2);
    std::string header;
    append<uint32_t>(header, uint32_t(data.size()));
    std::string temps;
    for (int i = 0; i < 24; ++i) temps += std::to_string(i) + " ";
    FieldSpec spec;
    spec.path = write("f.xml", vti("", "<DataArray type=\"Float32\" Name=\"velocity\" NumberOfComponents=\"3\" format=\"binary\">"
                                           + base64(header) + base64(data) + "</DataArray>\n"
                                           + "<DataArray type=\"Float32\" Name=\"temperature\" format=\"ascii\">" + temps + "</DataArray>\n"));
    expectInputError([&] { loadField(spec); }, {"f.xml", "--format"});
    spec.format = "vti";
    const LoadedField f = loadField(spec);
    ASSERT_TRUE(f.scalars.count("temperature"));
    const auto& t = *f.scalars.at("temperature");
    EXPECT_EQ(t.tree().getValue(openvdb::Coord(1, 2, 1)), float(1 + 2 * 4 + 1 * 12));
    EXPECT_EQ(t.transform(), f.velocity->transform());
    EXPECT_NEAR(f.velocity->indexToWorld(openvdb::Coord(0))[0], 1.0, 1e-12); // the file's origin
    EXPECT_NEAR(f.velocity->voxelSize()[0], 0.5, 1e-12);
}

TEST_F(TempDir, NanPolicy)
{
    std::string d = fieldData<float>(4, 3, 2, "xyzc");
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    // (X,Y,Z,3) C order: voxel (i,j,k) starts at float ((i*3 + j)*2 + k)*3.
    std::memcpy(&d[(((2 * 3 + 1) * 2 + 1) * 3 + 1) * 4], &nan, 4);
    std::memcpy(&d[(((3 * 3 + 2) * 2 + 0) * 3 + 0) * 4], &inf, 4);
    FieldSpec spec;
    spec.path = write("nan.npy", npy("<f4", false, "(4, 3, 2, 3)", d));
    spec.voxelSize = 2.0;
    expectInputError([&] { loadField(spec); }, {"nan.npy", "2 NaN or infinite", "voxel (2, 1, 1)", "world (4, 2, 2)", "--nan-policy zero"});
    spec.nanPolicy = "zero";
    const LoadedField f = loadField(spec);
    EXPECT_EQ(f.nonFiniteReplaced, 2u);
    EXPECT_EQ(f.velocity->tree().getValue(openvdb::Coord(2, 1, 1)), Vec3s(0.0f));
    EXPECT_EQ(f.velocity->tree().getValue(openvdb::Coord(3, 2, 0)), Vec3s(0.0f));
    EXPECT_EQ(f.velocity->tree().getValue(openvdb::Coord(1, 1, 1)), expected(1, 1, 1));
    ASSERT_FALSE(f.notes.empty());
    EXPECT_NE(f.notes[0].find("replaced 2"), std::string::npos);
}

TEST_F(TempDir, CropMaskAndResampleKeepWorldPosition)
{
    // A linear field v = (x, y, z) in world units on 8x8x8 voxels of size 0.5 at origin (10, 0, 0),
    // with a zero slab at i = 7.
    std::string d;
    for (int i = 0; i < 8; ++i) for (int j = 0; j < 8; ++j) for (int k = 0; k < 8; ++k) {
        const Vec3d w(10 + 0.5 * i, 0.5 * j, 0.5 * k);
        for (int c = 0; c < 3; ++c) append<float>(d, i == 7 ? 0.0f : float(w[c]));
    }
    FieldSpec spec;
    spec.path = write("lin.npy", npy("<f4", false, "(8, 8, 8, 3)", d));
    spec.voxelSize = 0.5;
    spec.origin = std::array<double, 3>{10, 0, 0};

    spec.mask = "zero";
    LoadedField f = loadField(spec);
    EXPECT_EQ(f.velocity->evalActiveVoxelBoundingBox(), openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(6, 7, 7)));

    spec.mask = "none";
    spec.crop = std::array<std::array<double, 3>, 2>{{{10.9, 0.4, -5}, {12.1, 1.6, 0.6}}};
    f = loadField(spec);
    // Voxel centres inside: x ∈ {11, 11.5, 12} → i 2..4; y ∈ {0.5, 1, 1.5} → j 1..3; z ∈ {0, 0.5} → k 0..1.
    EXPECT_EQ(f.velocity->evalActiveVoxelBoundingBox(), openvdb::CoordBBox(openvdb::Coord(2, 1, 0), openvdb::Coord(4, 3, 1)));
    spec.crop = std::array<std::array<double, 3>, 2>{{{0, 0, 0}, {1, 1, 1}}};
    expectInputError([&] { loadField(spec); }, {"crop box", "no voxel centre"});

    spec.crop.reset();
    spec.resample = 0.25;
    f = loadField(spec);
    EXPECT_NEAR(f.velocity->voxelSize()[0], 0.25, 1e-12);
    // Trilinear resampling reproduces a linear field exactly at world positions inside the data.
    const auto acc = f.velocity->getConstAccessor();
    int checked = 0;
    for (auto it = f.velocity->cbeginValueOn(); it; ++it) {
        const Vec3d w = f.velocity->indexToWorld(it.getCoord());
        if (w[0] > 12.9 || w[0] < 10 || w[1] > 3.5 || w[2] > 3.5 || w[1] < 0 || w[2] < 0) continue;
        for (int c = 0; c < 3; ++c) ASSERT_NEAR((*it)[c], w[c], 1e-4) << "at world " << w;
        ++checked;
    }
    EXPECT_GT(checked, 1000);
    // The first new voxel centre sits on the first old one.
    EXPECT_NEAR(f.velocity->indexToWorld(f.velocity->evalActiveVoxelBoundingBox().min())[0], 10.0, 1e-9);
}

TEST_F(TempDir, SplitComponentGrids)
{
    // Houdini-style vel.x / vel.y / vel.z float grids sharing one transform.
    openvdb::GridPtrVec grids;
    for (int c = 0; c < 3; ++c) {
        auto g = openvdb::FloatGrid::create(0.0f);
        g->setName(std::string("vel.") + "xyz"[c]);
        g->setTransform(openvdb::math::Transform::createLinearTransform(0.1));
        for (int i = 0; i < 4; ++i) for (int j = 0; j < 3; ++j) for (int k = 0; k < 2; ++k)
            g->tree().setValueOn(openvdb::Coord(i, j, k), expected(i, j, k)[c]);
        grids.push_back(g);
    }
    auto density = openvdb::FloatGrid::create(0.0f);
    density->setName("density");
    density->tree().setValueOn(openvdb::Coord(1), 1.0f);
    grids.push_back(density);
    FieldSpec spec;
    spec.path = (mDir / "split.vdb").string();
    writeVdbAtomic(spec.path, grids);
    const LoadedField f = loadField(spec);
    EXPECT_EQ(f.gridName, "vel");
    EXPECT_EQ(f.velocity->activeVoxelCount(), 24u);
    EXPECT_EQ(f.velocity->tree().getValue(openvdb::Coord(3, 1, 1)), expected(3, 1, 1));
    EXPECT_NEAR(f.velocity->voxelSize()[0], 0.1, 1e-12);
    EXPECT_TRUE(f.scalars.count("density"));
    // Naming the base explicitly works too.
    spec.grid = "vel";
    EXPECT_EQ(loadField(spec).velocity->tree().getValue(openvdb::Coord(2, 2, 0)), expected(2, 2, 0));
}

TEST_F(TempDir, StaggeredVdbKeepsClassAndTransform)
{
    auto g = openvdb::Vec3SGrid::create(Vec3s(0.0f));
    g->setName("velocity");
    g->setGridClass(openvdb::GRID_STAGGERED);
    auto xf = openvdb::math::Transform::createLinearTransform(0.375);
    xf->postTranslate(Vec3d(-2.0, -2.0, -1.0));
    g->setTransform(xf);
    for (int i = 1; i < 6; ++i) for (int j = 1; j < 6; ++j) for (int k = 1; k < 6; ++k)
        g->tree().setValueOn(openvdb::Coord(i, j, k), Vec3s(1, 0, 0));
    g->setSaveFloatAsHalf(true);
    FieldSpec spec;
    spec.path = (mDir / "mac.vdb").string();
    writeVdbAtomic(spec.path, {g});
    const LoadedField f = loadField(spec);
    EXPECT_EQ(f.velocity->getGridClass(), openvdb::GRID_STAGGERED);
    EXPECT_EQ(f.velocity->transform(), *xf);
    EXPECT_EQ(f.velocity->tree().getValue(openvdb::Coord(3)), Vec3s(1, 0, 0));
    // Resampling a staggered grid gives a cell-centred one at the requested voxel size.
    spec.resample = 0.75;
    const LoadedField r = loadField(spec);
    EXPECT_NE(r.velocity->getGridClass(), openvdb::GRID_STAGGERED);
    EXPECT_NEAR(r.velocity->voxelSize()[0], 0.75, 1e-12);
    expectInputError([&] {
        FieldSpec s = spec;
        s.voxelSize = 1.0;
        loadField(s);
    }, {"voxel_size", ".vdb"});
}
