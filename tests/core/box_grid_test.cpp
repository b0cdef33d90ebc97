// The broad phase of the collision-safe step (core/src/detail/box_grid.h, private to the core:
// included by path): against brute force, every overlapping box is reported exactly once, for
// boxes of mixed sizes, far from the origin, spanning many cells, huge or not finite.
#include "../../core/src/detail/box_grid.h"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

using riemesh::detail::Box6;
using riemesh::detail::boxesOverlap;
using riemesh::detail::CentreGrid;
using riemesh::detail::PackedBoxGrid;

namespace {

Box6 randomBox(std::mt19937& rng, double centre, double spread, double size)
{
    std::uniform_real_distribution<double> at(centre - spread, centre + spread);
    std::exponential_distribution<double> extent(1.0 / size);
    Box6 b;
    for (int k = 0; k < 3; ++k) {
        b[k] = at(rng);
        b[k + 3] = b[k] + extent(rng);
    }
    return b;
}

/// Each query's reports, sorted, against the overlapping boxes above `after` (brute force).
void checkAgainstBruteForce(const std::vector<Box6>& boxes, const std::vector<Box6>& queries, double cell)
{
    PackedBoxGrid grid;
    grid.build(boxes, cell);
    for (std::size_t q = 0; q < queries.size(); ++q) {
        const int after = int(q % 3 == 0 ? -1 : q % boxes.size());
        std::vector<int> got;
        grid.query(queries[q], [&](int item) { got.push_back(item); }, after);
        std::sort(got.begin(), got.end());
        std::vector<int> want;
        for (std::size_t i = 0; i < boxes.size(); ++i)
            if (int(i) > after && boxesOverlap(queries[q], boxes[i])) want.push_back(int(i));
        CAPTURE(q);
        REQUIRE(std::adjacent_find(got.begin(), got.end()) == got.end()); // each item once
        // Every overlapping box is reported; a report that brute force does not confirm may only
        // come from the float rounding (a box touching the query within a float's precision).
        CHECK(std::includes(got.begin(), got.end(), want.begin(), want.end()));
        for (int item : got) {
            Box6 grown = boxes[std::size_t(item)];
            for (int k = 0; k < 6; ++k) grown[k] += (k < 3 ? -1 : 1) * 1e-6 * (1 + std::abs(grown[k]));
            CHECK(boxesOverlap(queries[q], grown));
        }
    }
}

} // namespace

TEST_CASE("box grid: random boxes of mixed sizes, near and far from the origin, against brute force")
{
    std::mt19937 rng(7);
    for (double centre : {0.0, -350.0, 1.0e6}) {
        std::vector<Box6> boxes, queries;
        for (int i = 0; i < 600; ++i) boxes.push_back(randomBox(rng, centre, 30.0, i % 50 == 0 ? 25.0 : 1.5));
        for (int i = 0; i < 300; ++i) queries.push_back(randomBox(rng, centre, 32.0, i % 30 == 0 ? 40.0 : 1.0));
        for (double cell : {0.4, 2.0, 9.0}) checkAgainstBruteForce(boxes, queries, cell);
    }
}

TEST_CASE("box grid: thousands of boxes, against brute force")
{
    std::mt19937 rng(11);
    std::vector<Box6> boxes, queries;
    for (int i = 0; i < 9000; ++i) boxes.push_back(randomBox(rng, 5.0, 60.0, i % 97 == 0 ? 30.0 : 1.2));
    for (int i = 0; i < 400; ++i) queries.push_back(randomBox(rng, 5.0, 62.0, i % 40 == 0 ? 30.0 : 1.0));
    checkAgainstBruteForce(boxes, queries, 1.5);
}

namespace {

/// The pairs reported (`got`, in any order) against brute force: each once, every overlapping
/// pair of first x other (same: of first with itself, i < j), and only those (or boxes touching
/// within a float's precision).
void checkPairs(std::vector<std::pair<int, int>>& got, const std::vector<Box6>& first, const std::vector<Box6>& other,
                bool same)
{
    std::sort(got.begin(), got.end());
    REQUIRE(std::adjacent_find(got.begin(), got.end()) == got.end());
    std::vector<std::pair<int, int>> want;
    for (std::size_t i = 0; i < first.size(); ++i)
        for (std::size_t j = same ? i + 1 : 0; j < other.size(); ++j)
            if (boxesOverlap(first[i], other[j])) want.push_back({int(i), int(j)});
    CHECK(std::includes(got.begin(), got.end(), want.begin(), want.end()));
    for (const auto& [i, j] : got) {
        CHECK((!same || i < j));
        Box6 grown = first[std::size_t(i)];
        for (int k = 0; k < 6; ++k) grown[k] += (k < 3 ? -1 : 1) * 1e-6 * (1 + std::abs(grown[k]));
        CHECK(boxesOverlap(other[std::size_t(j)], grown));
    }
}

/// Grids of `first` and `second` (sparse or not; in the frame of both, or of `second` alone so
/// that some of first's boxes may lie outside it), paired: first x second (pairsAcross over
/// first's entries, in two halves as callers split them among threads, and pairsWithLarge), and
/// first with itself (pairsWithin, pairsWithLarge), against brute force.
void checkPairing(const std::vector<Box6>& first, const std::vector<Box6>& second, double cell, bool firstSparse,
                  bool secondSparse, bool frameOfSecond)
{
    const PackedBoxGrid::Frame frame =
        frameOfSecond ? PackedBoxGrid::frameFor({&second}, cell) : PackedBoxGrid::frameFor({&first, &second}, cell);
    PackedBoxGrid a, b;
    firstSparse ? a.buildSparse(first, frame) : a.build(first, frame);
    secondSparse ? b.buildSparse(second, frame) : b.build(second, frame);
    std::vector<std::pair<int, int>> got, gotSelf;
    const std::size_t half = a.entries() / 2;
    for (const auto& [e0, e1] : {std::pair<std::size_t, std::size_t>{0, half}, {half, a.entries()}}) {
        PackedBoxGrid::pairsAcross(a, b, e0, e1, [&](int x, int y) { got.push_back({x, y}); });
        a.pairsWithin(e0, e1, [&](int x, int y) { gotSelf.push_back({x, y}); });
    }
    PackedBoxGrid::pairsWithLarge(a, b, [&](int x, int y) { got.push_back({x, y}); });
    a.pairsWithLarge([&](int x, int y) { gotSelf.push_back({x, y}); });
    checkPairs(got, first, second, false);
    checkPairs(gotSelf, first, first, true);
}

} // namespace

TEST_CASE("box grid: a sparse grid paired with a dense one, with a sparse one and with itself, against brute force")
{
    // The collision-safe step pairs grids of its dirty primitives (few, in the anchored grids'
    // frame: some moved below or beyond the boxes that frame was made for) with the anchored grids.
    std::mt19937 rng(37);
    for (double centre : {0.0, 1.0e6}) {
        std::vector<Box6> dirty, anchored;
        for (int i = 0; i < 2000; ++i) anchored.push_back(randomBox(rng, centre, 20.0, i % 150 == 0 ? 200.0 : 1.5));
        for (int i = 0; i < 250; ++i) dirty.push_back(randomBox(rng, centre - 6.0, 30.0, i % 50 == 0 ? 0.0 : 1.0));
        dirty[3] = {centre - 400, centre - 400, centre - 400, centre - 399, centre - 399, centre - 399}; // (far below)
        dirty[9] = {std::nan(""), 0, 0, 1, 1, 1};
        for (double cell : {0.7, 2.5})
            for (bool secondSparse : {false, true}) {
                CAPTURE(centre);
                CAPTURE(cell);
                CAPTURE(secondSparse);
                checkPairing(dirty, anchored, cell, true, secondSparse, true);
            }
    }
}

TEST_CASE("box grid: pairing two grids, and one grid with itself, against brute force")
{
    // The broad phase of a collision-safe step from scratch pairs the vertices' grid with the
    // faces' and the edges' grid with itself, cell by cell: mixed sizes, boxes too large for the
    // cells (paired apart), bucket counts that differ (few boxes and many), NaN.
    std::mt19937 rng(31);
    for (double centre : {0.0, -350.0, 1.0e6}) {
        std::vector<Box6> small, large;
        for (int i = 0; i < 300; ++i) small.push_back(randomBox(rng, centre, 20.0, i % 60 == 0 ? 0.0 : 0.3));
        for (int i = 0; i < 1500; ++i) large.push_back(randomBox(rng, centre, 22.0, i % 100 == 0 ? 200.0 : 1.5));
        small[7] = {std::nan(""), 0, 0, 1, 1, 1};
        for (double cell : {0.5, 2.0}) {
            CAPTURE(centre);
            CAPTURE(cell);
            checkPairing(small, large, cell, false, false, false);
            checkPairing(large, small, cell, false, false, false);
        }
    }
}

TEST_CASE("box grid: a query long along z wraps around the buckets without reporting twice")
{
    // Few boxes (the fewest buckets) in one column; queries spanning up to the 64-cell limit
    // along z, and beyond it (the slow path).
    std::vector<Box6> boxes;
    for (int i = 0; i < 40; ++i) boxes.push_back({0.1, 0.1, double(i), 0.9, 0.9, double(i) + 0.5});
    std::vector<Box6> queries = {{0, 0, -3, 1, 1, 70}, {0, 0, 10, 1, 1, 74.5}, {0, 0, -100, 1, 1, 100},
                                 {0.5, 0.5, 5.2, 0.6, 0.6, 5.3}};
    checkAgainstBruteForce(boxes, queries, 1.0);
}

TEST_CASE("box grid: huge, infinite and NaN boxes neither crash nor hide the others")
{
    constexpr double inf = std::numeric_limits<double>::infinity();
    const double nan = std::nan("");
    std::vector<Box6> boxes = {{0, 0, 0, 1, 1, 1},       {-1e300, -1, -1, 1e300, 1, 1}, {-inf, -inf, -inf, inf, inf, inf},
                               {nan, 0, 0, 1, 1, 1},     {2, 2, 2, 3, 3, 3},            {1e20, 1e20, 1e20, 2e20, 2e20, 2e20},
                               {-5, -5, -5, -4.5, -4.5, -4.5}};
    PackedBoxGrid grid;
    grid.build(boxes, 1.0);
    auto reported = [&](const Box6& q) {
        std::vector<int> got;
        grid.query(q, [&](int item) { got.push_back(item); });
        std::sort(got.begin(), got.end());
        return got;
    };
    CHECK(reported({0.5, 0.5, 0.5, 0.6, 0.6, 0.6}) == std::vector<int>{0, 1, 2});
    CHECK(reported({2.5, 2.5, 2.5, 2.6, 2.6, 2.6}) == std::vector<int>{2, 4});
    CHECK(reported({-4.8, -4.8, -4.8, -4.7, -4.7, -4.7}) == std::vector<int>{2, 6});
    CHECK(reported({1.5e20, 1.5e20, 1.5e20, 1.6e20, 1.6e20, 1.6e20}) == std::vector<int>{2, 5});
    CHECK(reported({-inf, -inf, -inf, inf, inf, inf}) == std::vector<int>{0, 1, 2, 4, 5, 6});
    CHECK(reported({nan, nan, nan, nan, nan, nan}).empty());
}

TEST_CASE("hashed box grid: items given room up front are reported only once inserted, with their current box, once")
{
    // The intersection guard resets its grid with room for every face index, then inserts the
    // live faces and, after each edit, enters the edited faces again with their new boxes.
    using riemesh::detail::BoxGrid;
    std::mt19937 rng(23);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    for (std::size_t room : {std::size_t(0), std::size_t(500)}) {
        BoxGrid grid;
        grid.reset(2.0, 4 * 500 + 64, room);
        std::vector<Box6> box(500);
        std::vector<char> in(500, 0);
        for (std::size_t i = 0; i < 500; ++i) {
            box[i] = randomBox(rng, 0.0, 10.0, 1.5);
            if (unit(rng) < 0.8) grid.insert(int(i), box[i]), in[i] = 1; // (some are never entered)
        }
        // Entered again elsewhere, three times (the old entries stay, skipped); some of them once as
        // a box too large for the cells (kept apart), then small again.
        for (int again = 0; again < 3; ++again)
            for (std::size_t i = 0; i < 500; i += 7)
                if (in[i]) {
                    box[i] = randomBox(rng, 0.0, 10.0, again == 1 && i % 5 == 0 ? 300.0 : 1.5);
                    grid.insert(int(i), box[i]);
                }
        std::size_t reported = 0;
        for (int q = 0; q < 300; ++q) {
            const Box6 query = randomBox(rng, 0.0, 12.0, 3.0);
            std::vector<int> got;
            grid.query(query, [&](int item) { got.push_back(item); });
            std::sort(got.begin(), got.end()); // (each once: no duplicates removed)
            std::vector<int> want;
            for (std::size_t i = 0; i < 500; ++i)
                if (in[i] && boxesOverlap(query, box[i])) want.push_back(int(i));
            CAPTURE(q);
            CHECK(got == want);
            reported += got.size();
        }
        CHECK(reported > 300);
    }
}

TEST_CASE("hashed box grid: items entered again and again keep a bounded grid that still reports each once")
{
    // The collision-safe step's overlay enters a few hundred faces and edges again every step for
    // as long as the mesh is not anchored anew: the stale entries are dropped once they pile up,
    // and the queries report exactly as before.
    using riemesh::detail::BoxGrid;
    std::mt19937 rng(41);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    constexpr std::size_t kItems = 300;
    BoxGrid grid;
    grid.reset(1.0, 64, kItems);
    std::vector<Box6> box(kItems);
    std::vector<char> in(kItems, 0);
    std::size_t most = 0;
    for (int round = 0; round < 400; ++round) {
        for (int k = 0; k < 40; ++k) {
            const std::size_t i = std::size_t(unit(rng) * kItems) % kItems;
            if (unit(rng) < 0.1) {
                grid.erase(int(i));
                in[i] = 0;
            } else {
                box[i] = randomBox(rng, 0.0, 8.0, 0.8);
                grid.insert(int(i), box[i]);
                in[i] = 1;
            }
        }
        most = std::max(most, grid.entryCount());
        if (round % 50 != 49) continue;
        for (int q = 0; q < 40; ++q) {
            const Box6 query = randomBox(rng, 0.0, 9.0, 2.0);
            std::vector<int> got;
            grid.query(query, [&](int item) { got.push_back(item); });
            std::sort(got.begin(), got.end());
            std::vector<int> want;
            for (std::size_t i = 0; i < kItems; ++i)
                if (in[i] && boxesOverlap(query, box[i])) want.push_back(int(i));
            CAPTURE(round);
            CAPTURE(q);
            CHECK(got == want);
        }
    }
    // 16,000 insertions of boxes spanning about 8 cells each: without dropping the stale entries
    // the grid would hold over 100,000; the live ones are about 300 x 8.
    CHECK(most < 20000);
}

TEST_CASE("centre grid: items moved back and forth for thousands of steps stay bounded and are reported once")
{
    // The edit guard's grid is kept from one regularity step to the next (RegularityCache): faces
    // are entered again as they move, out of their cell and back into it. Entries of cells an
    // item has left, or entered again, are dropped once they pile up; queries report each item
    // whose box overlaps them exactly once.
    std::mt19937 rng(59);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    constexpr std::size_t kItems = 250;
    CentreGrid grid;
    grid.reset(1.0, kItems);
    std::vector<Box6> box(kItems), home(kItems);
    for (std::size_t i = 0; i < kItems; ++i) {
        home[i] = box[i] = randomBox(rng, 0.0, 6.0, 0.3);
        grid.insert(int(i), box[i]);
    }
    std::size_t most = 0;
    for (int round = 0; round < 300; ++round) {
        for (int k = 0; k < 60; ++k) { // moved to a neighbouring cell, or back home
            const std::size_t i = std::size_t(unit(rng) * kItems) % kItems;
            box[i] = home[i];
            if (unit(rng) < 0.5) {
                const double dx = unit(rng) < 0.5 ? -0.8 : 0.8;
                box[i][0] += dx, box[i][3] += dx;
            }
            grid.insert(int(i), box[i]);
        }
        most = std::max(most, grid.entryCount());
        if (round % 30 != 29) continue;
        for (int q = 0; q < 50; ++q) {
            const Box6 query = randomBox(rng, 0.0, 7.0, 1.5);
            std::vector<int> got, want;
            grid.query(query, [&](int item) { got.push_back(item); });
            std::sort(got.begin(), got.end());
            for (std::size_t i = 0; i < kItems; ++i)
                if (boxesOverlap(query, box[i])) want.push_back(int(i));
            CAPTURE(round);
            CAPTURE(q);
            CHECK(got == want); // (an item back in a cell it had an entry in: still once)
        }
    }
    CHECK(most < 4 * 512); // (the buckets for 250 items: 512; without dropping entries about 9,000)
}

TEST_CASE("centre grid: boxes entered by their centres, moved and re-entered, against brute force")
{
    // Every overlapping box reported exactly once and nothing else: boxes narrower and wider than
    // 0.9 cell (the wide ones are kept apart), near and far from the origin, then a third of them
    // entered again with new boxes (moved to another cell, moved within theirs, turned wide or
    // narrow), as the edit guard re-enters the faces an edit changed. Queries include huge ones.
    std::mt19937 rng(11);
    std::uniform_int_distribution<int> pick(0, 399);
    for (double centre : {0.0, -350.0, 1.0e6}) {
        for (double cell : {0.5, 2.0, 9.0}) {
            // Mostly boxes just under the 0.9-cell limit (the ones a query finds only through the
            // half cell it is grown by), some small, some wider than a cell.
            std::uniform_real_distribution<double> nearLimit(0.7 * cell, 0.9 * cell);
            auto sized = [&](double size) {
                if (size > 0) return randomBox(rng, centre, 30.0, size);
                Box6 b = randomBox(rng, centre, 30.0, 1.0);
                for (int k = 0; k < 3; ++k) b[k + 3] = b[k] + nearLimit(rng);
                return b;
            };
            std::vector<Box6> boxes;
            for (int i = 0; i < 400; ++i) boxes.push_back(sized(i % 40 == 0 ? 20.0 : (i % 4 == 0 ? 1.0 : 0.0)));
            CentreGrid grid;
            grid.reset(cell, boxes.size());
            for (std::size_t i = 0; i < boxes.size(); ++i) grid.insert(int(i), boxes[i]);
            for (int round = 0; round < 2; ++round) {
                for (int q = 0; q < 400; ++q) {
                    const Box6 query = q % 50 == 0 ? Box6{-1e300, -1e300, -1e300, 1e300, 1e300, 1e300}
                                                   : randomBox(rng, centre, 32.0, q % 25 == 0 ? 40.0 : (q % 2 ? 1.0 : 0.01));
                    std::vector<int> got, want;
                    grid.query(query, [&](int item) { got.push_back(item); });
                    std::sort(got.begin(), got.end());
                    for (std::size_t i = 0; i < boxes.size(); ++i)
                        if (boxesOverlap(query, boxes[i])) want.push_back(int(i));
                    CAPTURE(q);
                    CHECK(got == want);
                }
                for (int k = 0; k < 130; ++k) { // re-enter a third (some twice)
                    const int i = pick(rng);
                    const double size = k % 13 == 0 ? 20.0 : (k % 3 == 0 ? 0.05 : (k % 2 ? 1.0 : 0.0));
                    boxes[std::size_t(i)] = k % 5 == 0 ? boxes[std::size_t(i)] : sized(size);
                    grid.insert(i, boxes[std::size_t(i)]);
                }
            }
        }
    }
}
