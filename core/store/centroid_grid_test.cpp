#include "core/store/centroid_grid.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <string>
#include <vector>

namespace outcore {
namespace OUTCORE_UNITY_ID {

Aabb box(Vec3f lo, Vec3f hi) {
  Aabb b;
  b.extend(lo);
  b.extend(hi);
  return b;
}

Vec3f lerp(const Aabb& b, float tx, float ty, float tz) {
  return Vec3f(b.lo.x + (b.hi.x - b.lo.x) * tx, b.lo.y + (b.hi.y - b.lo.y) * ty,
               b.lo.z + (b.hi.z - b.lo.z) * tz);
}

TEST(CentroidGrid, CellOfStaysInRangeAndCornersMapToTheFirstAndLastCell) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (const uint32_t max_cells : {1u, 8u, 1000u, 1u << 18}) {
    SCOPED_TRACE(max_cells);
    const Aabb bounds = box({-3, -2, -1}, {5, 7, 11});
    const CentroidGrid grid(bounds, max_cells);
    ASSERT_GE(grid.cell_count(), 1u);
    EXPECT_LE(grid.cell_count(), max_cells);
    EXPECT_EQ(grid.cell_count(), grid.resolution()[0] * grid.resolution()[1] * grid.resolution()[2]);
    EXPECT_EQ(grid.cell_of(bounds.lo), 0u);
    EXPECT_EQ(grid.cell_of(bounds.hi), grid.cell_count() - 1);
    for (int i = 0; i < 10000; ++i) {
      ASSERT_LT(grid.cell_of(lerp(bounds, unit(rng), unit(rng), unit(rng))), grid.cell_count());
    }
  }
}

TEST(CentroidGrid, UsesMostOfTheCellBudgetWithRoughlyCubicCells) {
  const Aabb bounds = box({0, 0, 0}, {100, 10, 40});
  const uint32_t max_cells = 1u << 18;
  const CentroidGrid grid(bounds, max_cells);
  EXPECT_GE(grid.cell_count(), max_cells / 8);
  const Vec3f extent = bounds.extent();
  float smallest = 1e30f, largest = 0.0f;
  for (int axis = 0; axis < 3; ++axis) {
    const float size = extent[axis] / static_cast<float>(grid.resolution()[axis]);
    smallest = std::min(smallest, size);
    largest = std::max(largest, size);
  }
  EXPECT_LE(largest, 4.0f * smallest)
      << grid.resolution()[0] << " x " << grid.resolution()[1] << " x " << grid.resolution()[2];
}

TEST(CentroidGrid, CellIndexGrowsAlongEachAxis) {
  const Aabb bounds = box({0, 0, 0}, {1, 2, 3});
  const CentroidGrid grid(bounds, 512);
  const auto& res = grid.resolution();
  for (int axis = 0; axis < 3; ++axis) {
    uint32_t previous = 0;
    for (int step = 0; step <= 1000; ++step) {
      float t[3] = {0.5f, 0.5f, 0.5f};
      t[axis] = static_cast<float>(step) / 1000.0f;
      const uint32_t cell = grid.cell_of(lerp(bounds, t[0], t[1], t[2]));
      const uint32_t index[3] = {cell % res[0], (cell / res[0]) % res[1], cell / (res[0] * res[1])};
      ASSERT_GE(index[axis], previous) << "axis " << axis << " step " << step;
      previous = index[axis];
    }
    EXPECT_EQ(previous, res[axis] - 1) << "the far side must reach the last cell on axis " << axis;
  }
}

TEST(CentroidGrid, FlatAxesGetOneCellAndAPointGetsOneCellInAll) {
  const CentroidGrid flat(box({0, 0, 5}, {10, 10, 5}), 1024);
  EXPECT_EQ(flat.resolution()[2], 1u);
  EXPECT_GT(flat.resolution()[0], 1u);
  EXPECT_LE(flat.cell_count(), 1024u);
  EXPECT_LT(flat.cell_of({10, 10, 5}), flat.cell_count());

  const CentroidGrid point(box({1, 2, 3}, {1, 2, 3}), 1024);
  EXPECT_EQ(point.cell_count(), 1u);
  EXPECT_EQ(point.cell_of({1, 2, 3}), 0u);
}

// Histograms `points` on a grid over their bounds.
struct Histogram {
  CentroidGrid grid;
  std::vector<CellStats> cells;
};

Histogram histogram(const std::vector<Vec3f>& points, uint32_t max_cells) {
  Aabb bounds;
  for (const Vec3f& p : points) bounds.extend(p);
  Histogram h{CentroidGrid(bounds, max_cells), {}};
  h.cells.resize(h.grid.cell_count());
  for (const Vec3f& p : points) {
    CellStats& cell = h.cells[h.grid.cell_of(p)];
    ++cell.count;
    cell.bounds.extend(box(p - Vec3f(0.1f, 0.1f, 0.1f), p + Vec3f(0.1f, 0.1f, 0.1f)));
  }
  return h;
}

// Every non-empty cell is in a group, no empty cell is, every group is used,
// and a group holds at most max triangles unless it is a single cell.
void expect_valid_plan(const Histogram& h, const GroupPlan& plan, uint64_t max_group) {
  SCOPED_TRACE("max_group " + std::to_string(max_group));
  ASSERT_EQ(plan.cell_to_group.size(), h.cells.size());
  std::vector<uint64_t> totals(plan.group_count, 0), cells_in_group(plan.group_count, 0);
  for (size_t i = 0; i < h.cells.size(); ++i) {
    const uint32_t g = plan.cell_to_group[i];
    if (h.cells[i].count == 0) {
      EXPECT_EQ(g, GroupPlan::kNoGroup) << "empty cell " << i;
      continue;
    }
    ASSERT_LT(g, plan.group_count) << "non-empty cell " << i << " has no group";
    totals[g] += h.cells[i].count;
    ++cells_in_group[g];
  }
  uint64_t cell_total = 0, group_total = 0;
  for (const CellStats& cell : h.cells) cell_total += cell.count;
  for (const uint64_t t : totals) group_total += t;
  EXPECT_EQ(group_total, cell_total);
  for (uint32_t g = 0; g < plan.group_count; ++g) {
    EXPECT_GT(totals[g], 0u) << "group " << g << " is empty";
    if (cells_in_group[g] > 1) {
      EXPECT_LE(totals[g], max_group) << "group " << g << " of " << cells_in_group[g] << " cells";
    }
  }
}

std::vector<Vec3f> clustered_points(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> spread(0.0f, 1.0f);
  std::uniform_int_distribution<int> cluster(0, 9);
  std::vector<Vec3f> centres;
  for (int c = 0; c < 10; ++c) centres.push_back(Vec3f(37.0f * c, 11.0f * (c % 3), -5.0f * c * c));
  std::vector<Vec3f> points;
  for (size_t i = 0; i < n; ++i) {
    const Vec3f& c = centres[cluster(rng)];
    points.push_back(c + Vec3f(spread(rng), spread(rng), spread(rng)) * 3.0f);
  }
  return points;
}

TEST(CentroidGridPlan, CoversEveryNonEmptyCellWithGroupsNoLargerThanMax) {
  const auto points = clustered_points(200'000, 11);
  const Histogram h = histogram(points, 1u << 15);
  for (const uint64_t max_group : {uint64_t{500}, uint64_t{5000}, uint64_t{50'000}, uint64_t{199'999}}) {
    const GroupPlan plan = plan_groups(h.grid, h.cells, max_group);
    expect_valid_plan(h, plan, max_group);
    EXPECT_GT(plan.group_count, 1u);
  }
}

TEST(CentroidGridPlan, EverythingFittingGivesOneGroup) {
  const auto points = clustered_points(10'000, 12);
  const Histogram h = histogram(points, 4096);
  const GroupPlan plan = plan_groups(h.grid, h.cells, 10'000);
  expect_valid_plan(h, plan, 10'000);
  EXPECT_EQ(plan.group_count, 1u);
}

TEST(CentroidGridPlan, ASingleCellHoldingMoreThanMaxBecomesAGroupOfItsOwn) {
  // 30k points at one spot plus a sparse cloud around it.
  std::vector<Vec3f> points(30'000, Vec3f(0.5f, 0.5f, 0.5f));
  std::mt19937 rng(13);
  std::uniform_real_distribution<float> unit(-10.0f, 10.0f);
  for (int i = 0; i < 5000; ++i) points.push_back(Vec3f(unit(rng), unit(rng), unit(rng)));
  const Histogram h = histogram(points, 4096);
  const GroupPlan plan = plan_groups(h.grid, h.cells, 1000);
  expect_valid_plan(h, plan, 1000);
  const uint32_t heavy_cell = h.grid.cell_of(Vec3f(0.5f, 0.5f, 0.5f));
  ASSERT_GE(h.cells[heavy_cell].count, 30'000u);
  const uint32_t heavy_group = plan.cell_to_group[heavy_cell];
  ASSERT_LT(heavy_group, plan.group_count);
  for (size_t i = 0; i < h.cells.size(); ++i) {
    if (i != heavy_cell) {
      EXPECT_NE(plan.cell_to_group[i], heavy_group) << "cell " << i << " shares the heavy group";
    }
  }
}

TEST(CentroidGridPlan, AllInOneCellGivesOneGroupEvenAboveMax) {
  const std::vector<Vec3f> points(5000, Vec3f(1, 2, 3));
  const Histogram h = histogram(points, 4096);
  ASSERT_EQ(h.grid.cell_count(), 1u);
  const GroupPlan plan = plan_groups(h.grid, h.cells, 100);
  expect_valid_plan(h, plan, 100);
  EXPECT_EQ(plan.group_count, 1u);
}

}  // namespace OUTCORE_UNITY_ID
}  // namespace outcore
