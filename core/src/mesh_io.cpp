// Mesh files: OBJ, PLY (binary little/big-endian and ascii), OFF, STL (binary and ascii).
//
// Our own small readers and writers (no OpenMesh IO: this compiles under emscripten and is meant to
// be fuzzed). Every reader parses the whole file from memory with explicit bounds: declared counts
// are checked against the bytes that remain before anything is allocated, so a lying header cannot
// make us allocate more than a small multiple of the file size. Writers build the file in memory and
// hand it to writeFileAtomically (temporary file beside the target, then rename).
#include "riemesh/mesh_io.h"

#include <OpenMesh/Core/System/omstream.hh>

#include <algorithm>
#include <array>
#include <cctype>
#include <cstdarg>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace riemesh {
namespace {

// ---------------------------------------------------------------------------------------------
// Shared helpers
// ---------------------------------------------------------------------------------------------

std::string lowerCase(std::string s)
{
    for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

std::string inQuotes(std::string_view s) { return "'" + std::string(s) + "'"; }

/// Error raised while parsing; readMesh prefixes it with the file name.
struct ParseError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

[[noreturn]] void fail(const std::string& message) { throw ParseError(message); }

std::string atLine(int line) { return "line " + std::to_string(line) + ": "; }

/// What a reader produces: positions and triangles (polygons already fanned). `faceOf` gives, per
/// triangle, the number of the polygon it came from (for messages).
struct MeshData {
    std::vector<Mesh::Point> points;
    std::vector<std::array<std::int64_t, 3>> triangles;
    std::vector<std::size_t> faceOf;
    int indexBase = 0; ///< 1 for OBJ: indices in messages are shown as in the file

    void addPolygon(const std::vector<std::int64_t>& polygon, std::size_t face)
    {
        if (polygon.size() < 3)
            fail("face " + std::to_string(face + indexBase) + " has " + std::to_string(polygon.size()) +
                 " vertices (at least 3 needed)");
        for (std::size_t i = 1; i + 1 < polygon.size(); ++i) {
            triangles.push_back({polygon[0], polygon[i], polygon[i + 1]});
            faceOf.push_back(face);
        }
    }
};

/// Parses a floating-point token (the whole token must be a number). Non-finite values parse; the
/// caller checks finiteness to report them as such.
bool parseDouble(std::string_view token, double& value)
{
    char buffer[64];
    if (token.empty() || token.size() >= sizeof(buffer)) return false;
    std::memcpy(buffer, token.data(), token.size());
    buffer[token.size()] = '\0';
    char* end = nullptr;
    value = std::strtod(buffer, &end);
    return end == buffer + token.size();
}

bool parseInt(std::string_view token, std::int64_t& value)
{
    if (!token.empty() && token[0] == '+') token.remove_prefix(1);
    if (token.empty()) return false;
    auto result = std::from_chars(token.data(), token.data() + token.size(), value);
    return result.ec == std::errc() && result.ptr == token.data() + token.size();
}

/// Whitespace tokenizer over text that knows line numbers. `#` starts a comment when enabled.
class Tokens {
public:
    Tokens(std::string_view text, bool hashComments) : mText(text), mHashComments(hashComments) {}

    /// Next token, crossing line ends. False at the end of the text.
    bool next(std::string_view& token)
    {
        for (;;) {
            skipBlanks();
            if (mPos >= mText.size()) return false;
            char c = mText[mPos];
            if (c == '\n') { ++mPos; ++mLine; continue; }
            if (mHashComments && c == '#') { skipLine(); continue; }
            token = take();
            return true;
        }
    }

    /// Next token on the current line only. False at the end of the line (which is not consumed).
    bool nextOnLine(std::string_view& token)
    {
        skipBlanks();
        if (mPos >= mText.size() || mText[mPos] == '\n') return false;
        if (mHashComments && mText[mPos] == '#') {
            while (mPos < mText.size() && mText[mPos] != '\n') ++mPos;
            return false;
        }
        token = take();
        return true;
    }

    /// Skips to the start of the next line.
    void skipLine()
    {
        while (mPos < mText.size() && mText[mPos] != '\n') ++mPos;
        if (mPos < mText.size()) { ++mPos; ++mLine; }
    }

    /// The rest of the current line (without the line end), consumed.
    std::string_view restOfLine()
    {
        skipBlanks();
        std::size_t start = mPos;
        while (mPos < mText.size() && mText[mPos] != '\n') ++mPos;
        std::string_view rest = mText.substr(start, mPos - start);
        while (!rest.empty() && (rest.back() == '\r' || rest.back() == ' ' || rest.back() == '\t'))
            rest.remove_suffix(1);
        return rest;
    }

    int line() const { return mLine; }
    std::size_t remainingBytes() const { return mText.size() - std::min(mPos, mText.size()); }

    double nextNumber(const char* what)
    {
        std::string_view token;
        if (!next(token)) fail(atLine(mLine) + "file ends before " + what);
        double value;
        if (!parseDouble(token, value)) fail(atLine(mLine) + "malformed number " + inQuotes(token) + " in " + what);
        return value;
    }

    std::int64_t nextInteger(const char* what)
    {
        std::string_view token;
        if (!next(token)) fail(atLine(mLine) + "file ends before " + what);
        std::int64_t value;
        if (!parseInt(token, value)) fail(atLine(mLine) + "malformed integer " + inQuotes(token) + " in " + what);
        return value;
    }

private:
    static bool isBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }
    void skipBlanks()
    {
        while (mPos < mText.size() && isBlank(mText[mPos])) ++mPos;
    }
    std::string_view take()
    {
        std::size_t start = mPos;
        while (mPos < mText.size() && !isBlank(mText[mPos]) && mText[mPos] != '\n' &&
               !(mHashComments && mText[mPos] == '#'))
            ++mPos;
        return mText.substr(start, mPos - start);
    }

    std::string_view mText;
    std::size_t mPos = 0;
    int mLine = 1;
    bool mHashComments;
};

/// Declared element counts must fit in the bytes that follow (each record needs at least
/// `minBytesPerRecord` bytes), so a lying header cannot trigger a huge allocation.
void checkDeclaredCount(std::int64_t count, const char* what, std::size_t remaining, std::size_t minBytesPerRecord)
{
    if (count < 0) fail("negative " + std::string(what) + " count " + std::to_string(count));
    if (minBytesPerRecord > 0 && std::uint64_t(count) > remaining / minBytesPerRecord)
        fail("header declares " + std::to_string(count) + " " + what + " but only " + std::to_string(remaining) +
             " bytes follow (file truncated or header wrong)");
}

// ---------------------------------------------------------------------------------------------
// OBJ
// ---------------------------------------------------------------------------------------------

MeshData readObj(std::string_view text)
{
    MeshData data;
    data.indexBase = 1;
    Tokens tokens(text, true);
    std::string_view keyword, token;
    std::vector<std::int64_t> polygon;
    std::size_t faceCount = 0;
    while (tokens.next(keyword)) {
        const int line = tokens.line();
        if (keyword == "v") {
            double xyz[3];
            for (double& c : xyz) {
                if (!tokens.nextOnLine(token)) fail(atLine(line) + "vertex has fewer than 3 coordinates");
                if (!parseDouble(token, c)) fail(atLine(line) + "malformed number " + inQuotes(token));
            }
            data.points.emplace_back(xyz[0], xyz[1], xyz[2]);
        } else if (keyword == "f") {
            polygon.clear();
            while (tokens.nextOnLine(token)) {
                std::string_view first = token.substr(0, token.find('/'));
                std::int64_t index;
                if (!parseInt(first, index)) fail(atLine(line) + "malformed face index " + inQuotes(token));
                if (index == 0) fail(atLine(line) + "face index 0 (OBJ indices start at 1)");
                if (index < 0) {
                    index += std::int64_t(data.points.size()) + 1;
                    if (index < 1)
                        fail(atLine(line) + "relative face index " + inQuotes(first) + " points before the first vertex");
                }
                polygon.push_back(index - 1);
            }
            if (polygon.size() < 3)
                fail(atLine(line) + "face has " + std::to_string(polygon.size()) + " vertices (at least 3 needed)");
            data.addPolygon(polygon, faceCount++);
        }
        // Everything else (vn, vt, g, o, s, l, usemtl, mtllib, ...) is ignored.
        tokens.skipLine();
    }
    return data;
}

// ---------------------------------------------------------------------------------------------
// OFF
// ---------------------------------------------------------------------------------------------

MeshData readOff(std::string_view text)
{
    MeshData data;
    Tokens tokens(text, true);
    std::string_view keyword;
    if (!tokens.next(keyword)) fail("no OFF header");
    // OFF, COFF, NOFF, CNOFF, STOFF, ... (not 4OFF / nOFF, which are not 3D).
    const bool isOff = keyword.size() >= 3 && keyword.substr(keyword.size() - 3) == "OFF" &&
                       keyword.find_first_not_of("STCN") == keyword.size() - 3;
    if (!isOff) fail("not an OFF file (first word is " + inQuotes(keyword.substr(0, 40)) + ")");
    // The counts "nv nf ne" may follow on the header line or on the next one.
    std::int64_t counts[2] = {0, 0};
    int have = 0;
    std::string_view token;
    while (have < 2 && tokens.nextOnLine(token)) {
        if (token == "BINARY") fail("binary OFF is not supported");
        if (!parseInt(token, counts[have])) fail(atLine(tokens.line()) + "malformed count " + inQuotes(token));
        ++have;
    }
    for (; have < 2; ++have) counts[have] = tokens.nextInteger("the vertex and face counts");
    tokens.skipLine(); // the edge count, if any, is ignored
    checkDeclaredCount(counts[0], "vertices", tokens.remainingBytes(), 5);
    data.points.reserve(std::size_t(counts[0]));
    for (std::int64_t i = 0; i < counts[0]; ++i) {
        double xyz[3];
        for (double& c : xyz) c = tokens.nextNumber("vertex coordinates");
        data.points.emplace_back(xyz[0], xyz[1], xyz[2]);
        tokens.skipLine(); // colours, normals
    }
    checkDeclaredCount(counts[1], "faces", tokens.remainingBytes(), 7);
    std::vector<std::int64_t> polygon;
    for (std::int64_t f = 0; f < counts[1]; ++f) {
        std::int64_t n = tokens.nextInteger("a face");
        if (n < 3) fail(atLine(tokens.line()) + "face has " + std::to_string(n) + " vertices (at least 3 needed)");
        if (std::uint64_t(n) > tokens.remainingBytes() / 2)
            fail(atLine(tokens.line()) + "face declares " + std::to_string(n) + " vertices but the file ends first");
        polygon.resize(std::size_t(n));
        for (auto& index : polygon) index = tokens.nextInteger("face vertex indices");
        data.addPolygon(polygon, std::size_t(f));
        tokens.skipLine(); // colour
    }
    return data;
}

// ---------------------------------------------------------------------------------------------
// PLY
// ---------------------------------------------------------------------------------------------

enum class PlyType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

bool plyTypeFromName(std::string_view name, PlyType& type)
{
    static const std::pair<const char*, PlyType> names[] = {
        {"char", PlyType::Int8},     {"int8", PlyType::Int8},       {"uchar", PlyType::UInt8},
        {"uint8", PlyType::UInt8},   {"short", PlyType::Int16},     {"int16", PlyType::Int16},
        {"ushort", PlyType::UInt16}, {"uint16", PlyType::UInt16},   {"int", PlyType::Int32},
        {"int32", PlyType::Int32},   {"uint", PlyType::UInt32},     {"uint32", PlyType::UInt32},
        {"float", PlyType::Float32}, {"float32", PlyType::Float32}, {"double", PlyType::Float64},
        {"float64", PlyType::Float64}};
    for (const auto& [n, t] : names)
        if (name == n) { type = t; return true; }
    return false;
}

std::size_t plyTypeSize(PlyType type)
{
    switch (type) {
    case PlyType::Int8: case PlyType::UInt8: return 1;
    case PlyType::Int16: case PlyType::UInt16: return 2;
    case PlyType::Int32: case PlyType::UInt32: case PlyType::Float32: return 4;
    case PlyType::Float64: return 8;
    }
    return 0;
}

bool isIntegerType(PlyType type) { return type != PlyType::Float32 && type != PlyType::Float64; }

struct PlyProperty {
    std::string name;
    PlyType type = PlyType::Float32;
    bool isList = false;
    PlyType countType = PlyType::UInt8;
};

struct PlyElement {
    std::string name;
    std::int64_t count = 0;
    std::vector<PlyProperty> properties;
};

enum class PlyEncoding { Ascii, BinaryLittle, BinaryBig };

/// Reads binary scalars with bounds checks.
class BinaryCursor {
public:
    BinaryCursor(std::string_view data, std::size_t offset, bool bigEndian)
        : mData(data), mPos(offset), mBigEndian(bigEndian) {}

    std::size_t remaining() const { return mData.size() - mPos; }
    std::size_t offset() const { return mPos; }

    void need(std::size_t bytes, const std::string& what) const
    {
        if (bytes > remaining())
            fail("truncated binary data: " + what + " needs " + std::to_string(bytes) + " bytes at offset " +
                 std::to_string(mPos) + " but the file has " + std::to_string(mData.size()) + " bytes");
    }

    /// Reads one value of `type` (caller has checked the bytes are there).
    double read(PlyType type)
    {
        unsigned char b[8];
        const std::size_t n = plyTypeSize(type);
        std::memcpy(b, mData.data() + mPos, n);
        mPos += n;
        if (mBigEndian) std::reverse(b, b + n);
        // Assemble little-endian bytes into integers explicitly (host-endianness independent).
        std::uint64_t u = 0;
        for (std::size_t i = 0; i < n; ++i) u |= std::uint64_t(b[i]) << (8 * i);
        switch (type) {
        case PlyType::Int8: return double(std::int8_t(std::uint8_t(u)));
        case PlyType::UInt8: return double(std::uint8_t(u));
        case PlyType::Int16: return double(std::int16_t(std::uint16_t(u)));
        case PlyType::UInt16: return double(std::uint16_t(u));
        case PlyType::Int32: return double(std::int32_t(std::uint32_t(u)));
        case PlyType::UInt32: return double(std::uint32_t(u));
        case PlyType::Float32: {
            std::uint32_t bits = std::uint32_t(u);
            float f;
            std::memcpy(&f, &bits, 4);
            return double(f);
        }
        case PlyType::Float64: {
            double d;
            std::memcpy(&d, &u, 8);
            return d;
        }
        }
        return 0;
    }

    std::uint32_t readUInt32LE()
    {
        need(4, "a 32-bit count");
        std::uint32_t v = 0;
        for (int i = 0; i < 4; ++i) v |= std::uint32_t(static_cast<unsigned char>(mData[mPos + i])) << (8 * i);
        mPos += 4;
        return v;
    }

    float readFloatLE()
    {
        std::uint32_t bits = readUInt32LE();
        float f;
        std::memcpy(&f, &bits, 4);
        return f;
    }

    void skip(std::size_t bytes) { mPos += bytes; }

private:
    std::string_view mData;
    std::size_t mPos;
    bool mBigEndian;
};

MeshData readPly(std::string_view file)
{
    // Header: lines up to "end_header".
    if (file.substr(0, 3) != "ply" || file.size() < 4 || (file[3] != '\n' && file[3] != '\r'))
        fail("not a PLY file (missing 'ply' magic line)");
    Tokens header(file, false);
    header.skipLine();
    PlyEncoding encoding = PlyEncoding::Ascii;
    bool haveFormat = false, ended = false;
    std::vector<PlyElement> elements;
    std::string_view keyword, token;
    while (!ended && header.next(keyword)) {
        const int line = header.line();
        if (keyword == "format") {
            std::string_view fmt;
            if (!header.nextOnLine(fmt)) fail(atLine(line) + "format line without a format");
            if (fmt == "ascii") encoding = PlyEncoding::Ascii;
            else if (fmt == "binary_little_endian") encoding = PlyEncoding::BinaryLittle;
            else if (fmt == "binary_big_endian") encoding = PlyEncoding::BinaryBig;
            else fail(atLine(line) + "unknown PLY format " + inQuotes(fmt));
            haveFormat = true;
            header.skipLine();
        } else if (keyword == "comment" || keyword == "obj_info") {
            header.skipLine();
        } else if (keyword == "element") {
            PlyElement element;
            std::string_view name, count;
            if (!header.nextOnLine(name) || !header.nextOnLine(count)) fail(atLine(line) + "incomplete element line");
            element.name = std::string(name);
            if (!parseInt(count, element.count) || element.count < 0)
                fail(atLine(line) + "malformed element count " + inQuotes(count));
            elements.push_back(std::move(element));
            header.skipLine();
        } else if (keyword == "property") {
            if (elements.empty()) fail(atLine(line) + "property before any element");
            PlyProperty property;
            std::string_view type, name;
            if (!header.nextOnLine(type)) fail(atLine(line) + "incomplete property line");
            if (type == "list") {
                property.isList = true;
                std::string_view countType;
                if (!header.nextOnLine(countType) || !header.nextOnLine(type))
                    fail(atLine(line) + "incomplete list property line");
                if (!plyTypeFromName(countType, property.countType) || !isIntegerType(property.countType))
                    fail(atLine(line) + "bad list count type " + inQuotes(countType));
            }
            if (!plyTypeFromName(type, property.type)) fail(atLine(line) + "unknown property type " + inQuotes(type));
            if (!header.nextOnLine(name)) fail(atLine(line) + "property without a name");
            property.name = std::string(name);
            elements.back().properties.push_back(std::move(property));
            header.skipLine();
        } else if (keyword == "end_header") {
            ended = true;
            header.skipLine();
        } else {
            fail(atLine(line) + "unexpected header line starting with " + inQuotes(keyword.substr(0, 40)));
        }
    }
    if (!ended) fail("PLY header has no end_header line");
    if (!haveFormat) fail("PLY header has no format line");

    // Which element/properties we need.
    const PlyElement* vertexElement = nullptr;
    const PlyElement* faceElement = nullptr;
    int xyz[3] = {-1, -1, -1};
    int indicesProperty = -1;
    for (const auto& element : elements) {
        if (element.name == "vertex") {
            vertexElement = &element;
            for (int i = 0; i < int(element.properties.size()); ++i) {
                const auto& p = element.properties[std::size_t(i)];
                for (int k = 0; k < 3; ++k)
                    if (!p.isList && p.name == std::string(1, char('x' + k))) xyz[k] = i;
            }
        } else if (element.name == "face") {
            faceElement = &element;
            for (int i = 0; i < int(element.properties.size()); ++i) {
                const auto& p = element.properties[std::size_t(i)];
                if (p.isList && (p.name == "vertex_indices" || p.name == "vertex_index")) {
                    if (!isIntegerType(p.type)) fail("face list " + inQuotes(p.name) + " has a non-integer type");
                    indicesProperty = i;
                }
            }
        }
    }
    if (!vertexElement) fail("PLY file has no vertex element");
    if (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0) fail("PLY vertex element lacks an x, y or z property");
    if (!faceElement) fail("PLY file has no face element");
    if (indicesProperty < 0) fail("PLY face element has no vertex_indices list");

    MeshData data;
    const std::size_t dataStart = file.size() - header.remainingBytes();
    std::vector<double> scalars;
    std::vector<std::int64_t> polygon;

    if (encoding == PlyEncoding::Ascii) {
        Tokens body(file.substr(dataStart), false);
        const int lineOffset = header.line() - 1;
        auto where = [&] { return atLine(body.line() + lineOffset); };
        for (const auto& element : elements) {
            checkDeclaredCount(element.count, (element.name + " elements").c_str(), body.remainingBytes(),
                               std::max<std::size_t>(1, element.properties.size()));
            const bool isVertex = &element == vertexElement, isFace = &element == faceElement;
            if (isVertex) data.points.reserve(std::size_t(element.count));
            for (std::int64_t r = 0; r < element.count; ++r) {
                double point[3] = {0, 0, 0};
                for (int i = 0; i < int(element.properties.size()); ++i) {
                    const auto& p = element.properties[std::size_t(i)];
                    if (!p.isList) {
                        if (!body.next(token)) fail(where() + "file ends inside " + element.name + " " + std::to_string(r));
                        double value;
                        if (!parseDouble(token, value)) fail(where() + "malformed number " + inQuotes(token));
                        for (int k = 0; k < 3; ++k)
                            if (isVertex && i == xyz[k]) point[k] = value;
                        continue;
                    }
                    std::string_view countToken;
                    if (!body.next(countToken)) fail(where() + "file ends inside " + element.name + " " + std::to_string(r));
                    std::int64_t n;
                    if (!parseInt(countToken, n) || n < 0) fail(where() + "malformed list count " + inQuotes(countToken));
                    if (std::uint64_t(n) > body.remainingBytes() / 2 + 1)
                        fail(where() + "list of " + std::to_string(n) + " values but the file ends first");
                    const bool wanted = isFace && i == indicesProperty;
                    if (wanted) polygon.clear();
                    for (std::int64_t j = 0; j < n; ++j) {
                        if (!body.next(token)) fail(where() + "file ends inside a list");
                        if (wanted) {
                            std::int64_t index;
                            if (!parseInt(token, index)) fail(where() + "malformed vertex index " + inQuotes(token));
                            polygon.push_back(index);
                        } else {
                            double ignored;
                            if (!parseDouble(token, ignored)) fail(where() + "malformed number " + inQuotes(token));
                        }
                    }
                    if (wanted) data.addPolygon(polygon, std::size_t(r));
                }
                if (isVertex) data.points.emplace_back(point[0], point[1], point[2]);
            }
        }
        return data;
    }

    BinaryCursor cursor(file, dataStart, encoding == PlyEncoding::BinaryBig);
    for (const auto& element : elements) {
        // Minimum bytes per record: scalars, plus the count of each list.
        std::size_t minRecord = 0;
        bool fixedSize = true;
        for (const auto& p : element.properties) {
            minRecord += plyTypeSize(p.isList ? p.countType : p.type);
            fixedSize = fixedSize && !p.isList;
        }
        checkDeclaredCount(element.count, (element.name + " elements").c_str(), cursor.remaining(), minRecord);
        const bool isVertex = &element == vertexElement, isFace = &element == faceElement;
        if (!isVertex && !isFace && fixedSize) { // skip wholesale
            cursor.skip(std::size_t(element.count) * minRecord);
            continue;
        }
        if (isVertex) data.points.reserve(std::size_t(element.count));
        for (std::int64_t r = 0; r < element.count; ++r) {
            double point[3] = {0, 0, 0};
            for (int i = 0; i < int(element.properties.size()); ++i) {
                const auto& p = element.properties[std::size_t(i)];
                if (!p.isList) {
                    cursor.need(plyTypeSize(p.type), element.name + " " + std::to_string(r));
                    const double value = cursor.read(p.type);
                    for (int k = 0; k < 3; ++k)
                        if (isVertex && i == xyz[k]) point[k] = value;
                    continue;
                }
                cursor.need(plyTypeSize(p.countType), element.name + " " + std::to_string(r) + " list count");
                const double count = cursor.read(p.countType);
                if (count < 0) fail(element.name + " " + std::to_string(r) + ": negative list count");
                const std::size_t n = std::size_t(count);
                if (n > cursor.remaining() / plyTypeSize(p.type))
                    cursor.need(cursor.remaining() + 1, element.name + " " + std::to_string(r) + " list of " +
                                                            std::to_string(n) + " values");
                if (isFace && i == indicesProperty) {
                    polygon.resize(n);
                    for (auto& index : polygon) index = std::int64_t(cursor.read(p.type));
                    data.addPolygon(polygon, std::size_t(r));
                } else {
                    cursor.skip(n * plyTypeSize(p.type));
                }
            }
            if (isVertex) data.points.emplace_back(point[0], point[1], point[2]);
        }
    }
    return data;
}

// ---------------------------------------------------------------------------------------------
// STL
// ---------------------------------------------------------------------------------------------

/// STL stores every triangle corner; merge corners at exactly the same position (+0 == -0).
class PointMerger {
public:
    explicit PointMerger(MeshData& data) : mData(data) {}

    std::int64_t indexOf(double x, double y, double z)
    {
        Key key{{x + 0.0, y + 0.0, z + 0.0}}; // -0.0 + 0.0 == +0.0
        auto [it, inserted] = mIndex.try_emplace(key, std::int64_t(mData.points.size()));
        if (inserted) mData.points.emplace_back(x, y, z);
        return it->second;
    }

private:
    struct Key {
        std::array<double, 3> p;
        bool operator==(const Key& o) const { return p == o.p; }
    };
    struct Hash {
        std::size_t operator()(const Key& k) const
        {
            std::uint64_t h = 1469598103934665603ull;
            for (double d : k.p) {
                std::uint64_t bits;
                std::memcpy(&bits, &d, 8);
                h = (h ^ bits ^ (bits >> 29)) * 1099511628211ull;
            }
            return std::size_t(h ^ (h >> 32));
        }
    };
    MeshData& mData;
    std::unordered_map<Key, std::int64_t, Hash> mIndex;
};

MeshData readStlAscii(std::string_view text)
{
    MeshData data;
    PointMerger merger(data);
    Tokens tokens(text, false);
    std::string_view keyword;
    std::vector<std::int64_t> polygon;
    bool inLoop = false;
    std::size_t faceCount = 0;
    while (tokens.next(keyword)) {
        const int line = tokens.line();
        if (keyword == "solid" || keyword == "endsolid") {
            tokens.restOfLine(); // the name may contain anything
        } else if (keyword == "facet") {
            tokens.skipLine(); // the normal is recomputed from the corners
        } else if (keyword == "outer") {
            inLoop = true;
            polygon.clear();
            tokens.skipLine();
        } else if (keyword == "vertex") {
            if (!inLoop) fail(atLine(line) + "vertex outside an 'outer loop'");
            double xyz[3];
            for (double& c : xyz) c = tokens.nextNumber("vertex coordinates");
            for (double c : xyz)
                if (!std::isfinite(c)) fail(atLine(line) + "non-finite vertex coordinate");
            polygon.push_back(merger.indexOf(xyz[0], xyz[1], xyz[2]));
        } else if (keyword == "endloop") {
            if (!inLoop) fail(atLine(line) + "'endloop' without 'outer loop'");
            inLoop = false;
            if (polygon.size() < 3)
                fail(atLine(line) + "facet has " + std::to_string(polygon.size()) + " vertices (at least 3 needed)");
            data.addPolygon(polygon, faceCount++);
        } else if (keyword == "endfacet") {
            // nothing
        } else {
            fail(atLine(line) + "unexpected word " + inQuotes(keyword.substr(0, 40)) + " in ascii STL");
        }
    }
    if (inLoop) fail("file ends inside a facet");
    return data;
}

MeshData readStlBinary(std::string_view file)
{
    if (file.size() < 84)
        fail("truncated binary STL: " + std::to_string(file.size()) + " bytes, the header alone needs 84");
    BinaryCursor cursor(file, 80, false);
    const std::uint32_t count = cursor.readUInt32LE();
    if (std::uint64_t(count) > cursor.remaining() / 50)
        fail("truncated binary STL: header declares " + std::to_string(count) + " triangles (" +
             std::to_string(84 + 50 * std::uint64_t(count)) + " bytes) but the file has " +
             std::to_string(file.size()) + " bytes");
    MeshData data;
    PointMerger merger(data);
    data.points.reserve(count / 2 + 3);
    data.triangles.reserve(count);
    data.faceOf.reserve(count);
    std::vector<std::int64_t> polygon(3);
    for (std::uint32_t f = 0; f < count; ++f) {
        cursor.skip(12); // normal, recomputed
        for (auto& index : polygon) {
            float xyz[3];
            for (float& c : xyz) c = cursor.readFloatLE();
            for (float c : xyz)
                if (!std::isfinite(c)) fail("triangle " + std::to_string(f) + " has a non-finite vertex coordinate");
            index = merger.indexOf(xyz[0], xyz[1], xyz[2]);
        }
        cursor.skip(2); // attribute byte count
        data.addPolygon(polygon, f);
    }
    return data;
}

/// Binary STL headers may start with "solid" too; decide by the declared size, then by content.
MeshData readStl(std::string_view file)
{
    if (file.size() >= 84) {
        std::uint32_t count = 0;
        for (int i = 0; i < 4; ++i) count |= std::uint32_t(static_cast<unsigned char>(file[80 + i])) << (8 * i);
        if (84 + 50 * std::uint64_t(count) == file.size()) return readStlBinary(file);
    }
    std::size_t start = 0;
    while (start < file.size() && std::isspace(static_cast<unsigned char>(file[start]))) ++start;
    if (file.substr(start, 5) == "solid") {
        std::string_view head = file.substr(start, 1024);
        const bool printable = std::all_of(head.begin(), head.end(), [](char c) {
            return c == '\n' || c == '\r' || c == '\t' || (static_cast<unsigned char>(c) >= 32 && c != 127);
        });
        if (printable && (head.find("facet") != std::string_view::npos || head.find("endsolid") != std::string_view::npos))
            return readStlAscii(file);
    }
    return readStlBinary(file);
}

// ---------------------------------------------------------------------------------------------
// Building the mesh
// ---------------------------------------------------------------------------------------------

/// Silences OpenMesh's error stream while add_face probes faces we count ourselves.
class QuietOpenMesh {
public:
    QuietOpenMesh() : mWasEnabled(::omerr().is_enabled()) { ::omerr().disable(); }
    ~QuietOpenMesh()
    {
        if (mWasEnabled) ::omerr().enable();
    }
    QuietOpenMesh(const QuietOpenMesh&) = delete;
    QuietOpenMesh& operator=(const QuietOpenMesh&) = delete;

private:
    bool mWasEnabled;
};

/// Builds the mesh from checked data, dropping unreferenced vertices. Returns the number of faces
/// OpenMesh refused (non-manifold or inconsistently oriented).
std::size_t buildMesh(const MeshData& data, bool reversed, Mesh& mesh)
{
    mesh.clear();
    std::vector<int> map(data.points.size(), -1);
    for (const auto& t : data.triangles)
        for (auto i : t) map[std::size_t(i)] = 0;
    for (std::size_t i = 0; i < data.points.size(); ++i)
        if (map[i] == 0) map[i] = mesh.add_vertex(data.points[i]).idx();
    QuietOpenMesh quiet;
    std::size_t refused = 0;
    std::vector<VertexHandle> face(3);
    for (const auto& t : data.triangles) {
        face[0] = VertexHandle(map[std::size_t(t[0])]);
        face[1] = VertexHandle(map[std::size_t(t[reversed ? 2 : 1])]);
        face[2] = VertexHandle(map[std::size_t(t[reversed ? 1 : 2])]);
        if (!mesh.add_face(face).is_valid()) ++refused;
    }
    return refused;
}

Mesh meshFromData(const MeshData& data)
{
    if (data.triangles.empty()) fail("no faces");
    const auto n = std::int64_t(data.points.size());
    for (std::size_t i = 0; i < data.points.size(); ++i)
        for (int k = 0; k < 3; ++k)
            if (!std::isfinite(data.points[i][k]))
                fail("vertex " + std::to_string(i + std::size_t(data.indexBase)) + " has a non-finite coordinate");
    for (std::size_t t = 0; t < data.triangles.size(); ++t) {
        const auto& tri = data.triangles[t];
        const std::string face = "face " + std::to_string(data.faceOf[t] + std::size_t(data.indexBase));
        for (auto i : tri)
            if (i < 0 || i >= n)
                fail(face + " refers to vertex " + std::to_string(i + data.indexBase) + " but the file has " +
                     std::to_string(n) + " vertices");
        if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2])
            fail(face + " is degenerate (uses vertex " +
                 std::to_string((tri[0] == tri[1] || tri[0] == tri[2] ? tri[0] : tri[1]) + data.indexBase) +
                 " twice)");
    }

    Mesh mesh;
    if (const std::size_t refused = buildMesh(data, false, mesh))
        fail(std::to_string(refused) + " of " + std::to_string(data.triangles.size()) +
             " triangles could not be added (non-manifold edges or vertices, or inconsistent orientation)");

    // Closed and manifold: no boundary, and each vertex's single fan holds all its faces.
    std::size_t boundary = 0;
    for (auto h : mesh.halfedges())
        if (mesh.is_boundary(h)) ++boundary;
    if (boundary > 0) fail("mesh is not closed (" + std::to_string(boundary) + " boundary edges)");
    std::vector<std::size_t> corners(mesh.n_vertices(), 0);
    for (auto f : mesh.faces())
        for (auto v : mesh.fv_range(f)) ++corners[std::size_t(v.idx())];
    // A closed manifold vertex has as many neighbours as faces in its fan; one with two sits on two
    // faces with the same three corners (a "pillow": e.g. an STL facet that repeats a corner,
    // fanned into a triangle and its reverse).
    std::size_t nonManifold = 0, pinched = 0;
    for (auto v : mesh.vertices()) {
        std::size_t fan = 0;
        for (auto f : mesh.vf_range(v)) { (void)f; ++fan; }
        if (fan != corners[std::size_t(v.idx())]) ++nonManifold;
        pinched += fan < 3;
    }
    if (nonManifold > 0) fail("mesh has " + std::to_string(nonManifold) + " non-manifold vertices");
    if (pinched > 0)
        fail("mesh has " + std::to_string(pinched) +
             " vertices with fewer than 3 neighbours (two faces on the same three corners)");

    if (signedVolume(mesh) < 0) buildMesh(data, true, mesh); // inside-out file: make normals point out
    prepareMesh(mesh);
    return mesh;
}

// ---------------------------------------------------------------------------------------------
// Writing
// ---------------------------------------------------------------------------------------------

/// The mesh as dense arrays: deleted elements skipped, faces oriented outward.
struct DenseMesh {
    std::vector<Vec3> points;
    std::vector<std::array<std::uint32_t, 3>> triangles;
};

DenseMesh denseMesh(const Mesh& mesh)
{
    DenseMesh dense;
    std::vector<std::int64_t> map(mesh.n_vertices(), -1);
    for (auto v : mesh.vertices()) {
        const Vec3 p = position(mesh, v);
        if (!p.allFinite())
            throw std::runtime_error("vertex " + std::to_string(v.idx()) + " has a non-finite position");
        map[std::size_t(v.idx())] = std::int64_t(dense.points.size());
        dense.points.push_back(p);
    }
    if (dense.points.size() > std::numeric_limits<std::int32_t>::max())
        throw std::runtime_error("too many vertices for the file format");
    const bool flip = signedVolume(mesh) < 0;
    for (auto f : mesh.faces()) {
        std::array<std::uint32_t, 3> tri{};
        int k = 0;
        for (auto v : mesh.fv_range(f)) {
            if (k == 3) throw std::runtime_error("face " + std::to_string(f.idx()) + " is not a triangle");
            const std::int64_t i = map[std::size_t(v.idx())];
            if (i < 0) throw std::runtime_error("face " + std::to_string(f.idx()) + " uses a deleted vertex");
            tri[std::size_t(k++)] = std::uint32_t(i);
        }
        if (k != 3) throw std::runtime_error("face " + std::to_string(f.idx()) + " is not a triangle");
        if (flip) std::swap(tri[1], tri[2]);
        dense.triangles.push_back(tri);
    }
    return dense;
}

void appendf(std::string& out, const char* format, ...) __attribute__((format(printf, 2, 3)));
void appendf(std::string& out, const char* format, ...)
{
    char buffer[256];
    va_list args;
    va_start(args, format);
    const int n = std::vsnprintf(buffer, sizeof(buffer), format, args);
    va_end(args);
    if (n > 0) out.append(buffer, std::size_t(std::min<int>(n, int(sizeof(buffer)) - 1)));
}

/// `comment` as header lines, each line prefixed (the comment may span lines).
void appendCommentLines(std::string& out, const std::string& comment, const char* prefix)
{
    if (comment.empty()) return;
    std::size_t start = 0;
    for (;;) {
        std::size_t end = comment.find('\n', start);
        std::string line = comment.substr(start, end == std::string::npos ? std::string::npos : end - start);
        if (!line.empty() && line.back() == '\r') line.pop_back();
        out += prefix;
        out += line;
        out += '\n';
        if (end == std::string::npos) break;
        start = end + 1;
    }
}

void appendUInt32LE(std::string& out, std::uint32_t v)
{
    for (int i = 0; i < 4; ++i) out += char((v >> (8 * i)) & 0xff);
}

void appendFloatLE(std::string& out, float f)
{
    std::uint32_t bits;
    std::memcpy(&bits, &f, 4);
    appendUInt32LE(out, bits);
}

float toFloat(double d)
{
    const float f = float(d);
    if (!std::isfinite(f)) throw std::runtime_error("coordinate " + std::to_string(d) + " does not fit in a float");
    return f;
}

std::string objText(const DenseMesh& m, const std::string& comment)
{
    std::string out;
    appendCommentLines(out, comment, "# ");
    for (const auto& p : m.points) appendf(out, "v %.17g %.17g %.17g\n", p.x(), p.y(), p.z());
    for (const auto& t : m.triangles) appendf(out, "f %u %u %u\n", t[0] + 1, t[1] + 1, t[2] + 1);
    return out;
}

std::string offText(const DenseMesh& m, const std::string& comment)
{
    // The comment goes after the data: many OFF readers (OpenMesh's among them) read the counts
    // right after the "OFF" line and fail on a comment there, while all of them stop after the faces.
    std::string out = "OFF\n";
    appendf(out, "%zu %zu 0\n", m.points.size(), m.triangles.size());
    for (const auto& p : m.points) appendf(out, "%.17g %.17g %.17g\n", p.x(), p.y(), p.z());
    for (const auto& t : m.triangles) appendf(out, "3 %u %u %u\n", t[0], t[1], t[2]);
    appendCommentLines(out, comment, "# ");
    return out;
}

std::string plyText(const DenseMesh& m, const std::string& comment, bool ascii)
{
    std::string out = "ply\n";
    out += ascii ? "format ascii 1.0\n" : "format binary_little_endian 1.0\n";
    appendCommentLines(out, comment, "comment ");
    appendf(out, "element vertex %zu\n", m.points.size());
    out += "property float x\nproperty float y\nproperty float z\n";
    appendf(out, "element face %zu\n", m.triangles.size());
    out += "property list uchar int vertex_indices\nend_header\n";
    if (ascii) {
        for (const auto& p : m.points)
            appendf(out, "%.9g %.9g %.9g\n", double(toFloat(p.x())), double(toFloat(p.y())), double(toFloat(p.z())));
        for (const auto& t : m.triangles) appendf(out, "3 %u %u %u\n", t[0], t[1], t[2]);
        return out;
    }
    out.reserve(out.size() + 12 * m.points.size() + 13 * m.triangles.size());
    for (const auto& p : m.points)
        for (int k = 0; k < 3; ++k) appendFloatLE(out, toFloat(p[k]));
    for (const auto& t : m.triangles) {
        out += char(3);
        for (auto i : t) appendUInt32LE(out, i);
    }
    return out;
}

std::string stlBinary(const DenseMesh& m, const std::string& comment)
{
    // An 80-byte header that must not start with "solid" (readers would take it for ascii STL).
    std::string header = comment.empty() ? std::string("binary STL written by riemesh") : comment;
    for (char& c : header)
        if (c == '\n' || c == '\r') c = ' ';
    if (lowerCase(header.substr(0, 5)) == "solid") header = "riemesh " + header;
    header.resize(80, ' ');
    std::string out = header;
    out.reserve(84 + 50 * m.triangles.size());
    appendUInt32LE(out, std::uint32_t(m.triangles.size()));
    for (const auto& t : m.triangles) {
        const Vec3 &a = m.points[t[0]], &b = m.points[t[1]], &c = m.points[t[2]];
        Vec3 n = (b - a).cross(c - a);
        const double len = n.norm();
        n = len > 0 ? Vec3(n / len) : Vec3::Zero();
        for (int k = 0; k < 3; ++k) appendFloatLE(out, float(n[k]));
        for (const Vec3* p : {&a, &b, &c})
            for (int k = 0; k < 3; ++k) appendFloatLE(out, toFloat((*p)[k]));
        out += '\0';
        out += '\0';
    }
    return out;
}

std::string errnoText(int error) { return std::strerror(error); }

std::string parentFolder(const std::string& path)
{
    const std::size_t slash = path.find_last_of('/');
    if (slash == std::string::npos) return ".";
    if (slash == 0) return "/";
    return path.substr(0, slash);
}

/// Writes `bytes` to a temporary file beside `path`, then renames it over `path`. On failure the
/// temporary file is removed and std::runtime_error names the path and the reason.
void writeFileAtomically(const std::string& path, const std::string& bytes)
{
    const std::string what = "cannot write mesh '" + path + "': ";
    const std::string folder = parentFolder(path);
    struct stat st {};
    if (::stat(folder.c_str(), &st) != 0) throw std::runtime_error(what + "folder '" + folder + "' does not exist");
    if (!S_ISDIR(st.st_mode)) throw std::runtime_error(what + "'" + folder + "' is not a folder");

    // Keep the target's permissions when replacing it, otherwise the usual 0666 & ~umask.
    mode_t mode;
    if (::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode)) {
        mode = st.st_mode & 07777;
    } else {
        const mode_t mask = ::umask(0);
        ::umask(mask);
        // Owner read/write always: emscripten's default umask is 0777, which would give mode 0.
        mode = (0666 & ~mask) | S_IRUSR | S_IWUSR;
    }

    std::vector<char> name(path.begin(), path.end());
    const char suffix[] = ".tmp-XXXXXX";
    name.insert(name.end(), suffix, suffix + sizeof(suffix)); // includes the terminating NUL
    const int fd = ::mkstemp(name.data());
    if (fd < 0) throw std::runtime_error(what + "cannot create a temporary file in '" + folder + "': " + errnoText(errno));
    const std::string tmp(name.data());

    auto abandon = [&](const std::string& reason, int error) {
        ::unlink(tmp.c_str());
        throw std::runtime_error(what + reason + ": " + errnoText(error));
    };

    std::size_t written = 0;
    while (written < bytes.size()) {
        const ssize_t n = ::write(fd, bytes.data() + written, bytes.size() - written);
        if (n < 0) {
            if (errno == EINTR) continue;
            const int error = errno;
            ::close(fd);
            abandon("write failed", error);
        }
        written += std::size_t(n);
    }
    ::fchmod(fd, mode); // best effort: the file is complete either way
    if (::fsync(fd) != 0 && errno != EINVAL && errno != EROFS && errno != ENOTSUP) {
        const int error = errno;
        ::close(fd);
        abandon("flushing to disk failed", error);
    }
    if (::close(fd) != 0) abandon("closing the temporary file failed", errno);
    if (std::rename(tmp.c_str(), path.c_str()) != 0) abandon("renaming the temporary file over it failed", errno);
}

std::string readWholeFile(const std::string& path)
{
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) throw ParseError("cannot open: " + errnoText(errno));
    if (S_ISDIR(st.st_mode)) throw ParseError("is a folder, not a file");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw ParseError("cannot open: " + errnoText(errno));
    std::string bytes;
    char buffer[1 << 16];
    while (in.read(buffer, sizeof(buffer)) || in.gcount() > 0) bytes.append(buffer, std::size_t(in.gcount()));
    if (in.bad()) throw ParseError("read error");
    return bytes;
}

} // namespace

MeshFormat meshFormatFromPath(const std::string& path)
{
    const std::size_t slash = path.find_last_of('/');
    const std::size_t dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash))
        throw std::invalid_argument("mesh path '" + path + "' has no extension (use .obj, .ply, .off or .stl)");
    const std::string ext = lowerCase(path.substr(dot));
    if (ext == ".obj") return MeshFormat::Obj;
    if (ext == ".ply") return MeshFormat::Ply;
    if (ext == ".off") return MeshFormat::Off;
    if (ext == ".stl") return MeshFormat::Stl;
    throw std::invalid_argument("unknown mesh extension '" + path.substr(dot) + "' (use .obj, .ply, .off or .stl)");
}

Mesh readMesh(const std::string& path)
{
    const MeshFormat format = meshFormatFromPath(path);
    std::string bytes;
    try {
        bytes = readWholeFile(path);
    } catch (const ParseError& e) {
        throw std::runtime_error("cannot read mesh '" + path + "': " + e.what());
    } catch (const std::bad_alloc&) {
        throw std::runtime_error("cannot read mesh '" + path + "': out of memory");
    }
    return readMeshFromBytes(bytes, format, path);
}

Mesh readMeshFromBytes(std::string_view bytes, MeshFormat format, const std::string& path)
{
    try {
        if (bytes.empty()) throw ParseError("file is empty");
        MeshData data;
        switch (format) {
        case MeshFormat::Obj: data = readObj(bytes); break;
        case MeshFormat::Ply:
        case MeshFormat::PlyAscii: data = readPly(bytes); break;
        case MeshFormat::Off: data = readOff(bytes); break;
        case MeshFormat::Stl: data = readStl(bytes); break;
        }
        return meshFromData(data);
    } catch (const ParseError& e) {
        throw std::runtime_error("cannot read mesh '" + path + "': " + e.what());
    } catch (const std::bad_alloc&) {
        throw std::runtime_error("cannot read mesh '" + path + "': out of memory");
    }
}

void writeMesh(const std::string& path, const Mesh& mesh, const std::string& comment)
{
    writeMesh(path, mesh, meshFormatFromPath(path), comment);
}

void writeMesh(const std::string& path, const Mesh& mesh, MeshFormat format, const std::string& comment)
{
    std::string bytes;
    try {
        const DenseMesh dense = denseMesh(mesh);
        switch (format) {
        case MeshFormat::Obj: bytes = objText(dense, comment); break;
        case MeshFormat::Ply: bytes = plyText(dense, comment, false); break;
        case MeshFormat::PlyAscii: bytes = plyText(dense, comment, true); break;
        case MeshFormat::Off: bytes = offText(dense, comment); break;
        case MeshFormat::Stl: bytes = stlBinary(dense, comment); break;
        }
    } catch (const std::runtime_error& e) {
        throw std::runtime_error("cannot write mesh '" + path + "': " + e.what());
    }
    writeFileAtomically(path, bytes);
}

} // namespace riemesh
