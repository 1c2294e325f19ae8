// Neighbourhoods against brute force, hand-made ball-query cases, and normals.
#include "dataset/neighbours.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <limits>
#include <random>
#include <thread>

namespace layersnet::dataset {
namespace {

Points random_points(int n, float extent, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-extent, extent);
  Points p(n, 3);
  for (int i = 0; i < n; ++i) p.row(i) << u(rng), u(rng), u(rng);
  return p;
}

TEST(Normals, TetrahedronNormalsPointOutward) {
  Points x(4, 3);
  x << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  Faces f(4, 3);
  f << 0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3;  // outward
  const Points n = vertex_normals(x, f);
  const Eigen::RowVector3f centre = x.colwise().mean();
  for (int v = 0; v < 4; ++v) {
    EXPECT_NEAR(n.row(v).norm(), 1.f, 1e-6f);
    EXPECT_GT(n.row(v).dot(x.row(v) - centre), 0.f) << v;
  }
  // Vertex 0 touches three axis-aligned faces: normal (-1, -1, -1)/sqrt(3).
  EXPECT_NEAR(n(0, 0), -1.f / std::sqrt(3.f), 1e-6f);
}

TEST(Normals, ZeroAreaFacesStayFinite) {
  Points x(5, 3);
  x << 0, 0, 0, 1, 0, 0, 0, 1, 0, 2, 0, 0, 3, 0, 0;  // face (1,3,4) is collinear
  Faces f(3, 3);
  f << 0, 1, 2, 1, 3, 4, 2, 2, 2;
  const Points n = vertex_normals(x, f);
  EXPECT_TRUE(n.allFinite());
  EXPECT_NEAR(n(0, 2), 1.f, 1e-6f);
  EXPECT_EQ(n.row(4), Eigen::RowVector3f(0, 0, 1));  // only a degenerate face: fallback
  EXPECT_EQ(n.row(3), Eigen::RowVector3f(0, 0, 1));
  EXPECT_NEAR(n(1, 2), 1.f, 1e-6f);  // the degenerate face adds nothing
}

TEST(WorldEdges, MatchesBruteForceAndExcludesMeshAdjacentPairs) {
  const Points c = random_points(400, 2.f, 3);
  const float R = 0.4f;
  // Mesh adjacency: i ~ i+1 (and self).
  Csr adj;
  for (int i = 0; i < 400; ++i) {
    for (int j : {i - 1, i, i + 1})
      if (j >= 0 && j < 400) adj.items.push_back(j);
    adj.offsets.push_back(static_cast<int32_t>(adj.items.size()));
  }
  const Csr w = world_edges(c, adj, R);
  int total = 0;
  for (int i = 0; i < 400; ++i) {
    std::vector<int32_t> want;
    for (int j = 0; j < 400; ++j)
      if (j != i && std::abs(j - i) != 1 && (c.row(i) - c.row(j)).norm() < R) want.push_back(j);
    EXPECT_EQ(std::vector<int32_t>(w.begin(i), w.end(i)), want) << i;
    total += static_cast<int>(want.size());
  }
  EXPECT_GT(total, 100);  // the test exercises real neighbourhoods
}

TEST(WorldEdges, DistanceExactlyRIsNotAnEdge) {
  Points c(3, 3);
  c << 0, 0, 0, 0.5f, 0, 0, 0.25f, 0, 0;
  Csr adj;
  for (int i = 0; i < 3; ++i) {
    adj.items.push_back(i);
    adj.offsets.push_back(i + 1);
  }
  const Csr w = world_edges(c, adj, 0.5f);
  EXPECT_EQ(std::vector<int32_t>(w.begin(0), w.end(0)), std::vector<int32_t>{2});
  EXPECT_EQ(std::vector<int32_t>(w.begin(1), w.end(1)), std::vector<int32_t>{2});
}

TEST(BodyNeighbours, OfficialFirstInIndexOrderVersusNearest) {
  // Body vertices on the x axis; vertex i at x = 0.1 * (9 - i): index 9 is the nearest.
  Points body(10, 3);
  for (int i = 0; i < 10; ++i) body.row(i) << 0.1f * (9 - i), 0, 0;
  Points q(3, 3);
  q << 0, 0, 0,  // hits: x < 0.55 -> i = 4..9
      5, 5, 5,   // nothing
      1.4f, 0, 0;  // only vertex 0 (distance 0.5)
  NeighbourOptions o;
  o.body_radius = 0.55f;
  o.body_k = 3;
  const BodyNeighbours first = body_neighbours(q, body, o);
  EXPECT_EQ(first.index.row(0), (Eigen::RowVector3i(4, 5, 6)).cast<int32_t>());
  EXPECT_EQ(first.hits[0], 3);
  // No hit: index 0, invalid. One hit: repeated, valid (official duplicates).
  EXPECT_EQ(first.index.row(1), (Eigen::RowVector3i(0, 0, 0)).cast<int32_t>());
  EXPECT_EQ(first.valid.row(1).cast<int>().sum(), 0);
  EXPECT_EQ(first.index.row(2), (Eigen::RowVector3i(0, 0, 0)).cast<int32_t>());
  EXPECT_EQ(first.valid.row(2).cast<int>().sum(), 3);
  EXPECT_EQ(first.hits[2], 1);
  o.body_query = BodyQuery::kNearest;
  o.official_padding = false;
  const BodyNeighbours near = body_neighbours(q, body, o);
  EXPECT_EQ(near.index.row(0), (Eigen::RowVector3i(9, 8, 7)).cast<int32_t>());
  EXPECT_EQ(near.valid.row(2).cast<int>().sum(), 1);
}

TEST(BodyNeighbours, MatchesBruteForceOnRandomClouds) {
  const Points body = random_points(3000, 1.5f, 5), q = random_points(200, 1.5f, 6);
  for (BodyQuery mode : {BodyQuery::kFirstInIndexOrder, BodyQuery::kNearest}) {
    NeighbourOptions o;
    o.body_query = mode;
    const BodyNeighbours nb = body_neighbours(q, body, o);
    for (int i = 0; i < 200; ++i) {
      std::vector<std::pair<float, int32_t>> all;
      for (int b = 0; b < 3000; ++b) {
        const float d2 = (q.row(i) - body.row(b)).squaredNorm();
        if (d2 < 0.36f) all.emplace_back(mode == BodyQuery::kNearest ? d2 : 0.f, b);
      }
      std::sort(all.begin(), all.end());
      const int n = std::min<int>(16, static_cast<int>(all.size()));
      ASSERT_EQ(nb.hits[i], n);
      for (int s = 0; s < n; ++s) EXPECT_EQ(nb.index(i, s), all[s].second);
    }
  }
}

TEST(NearestBody, MatchesBruteForce) {
  const Points body = random_points(2000, 1.f, 7), q = random_points(300, 1.5f, 8);
  const NearestBody nb = nearest_body(q, body);
  for (int i = 0; i < 300; ++i) {
    Eigen::Index best;
    const float d = std::sqrt((body.rowwise() - q.row(i)).rowwise().squaredNorm().minCoeff(&best));
    EXPECT_NEAR(nb.distance[i], d, 1e-5f);
    EXPECT_NEAR((body.row(nb.index[i]) - q.row(i)).norm(), d, 1e-5f);
  }
}

// Within the bound the bounded search answers as the unbounded one (same index, same distance),
// beyond it nothing; a point at exactly the bound is found.
TEST(NearestBody, BoundedSearchAgreesWithinTheBoundAndFindsNothingBeyond) {
  const Points body = random_points(2000, 1.f, 7), q = random_points(3000, 1.5f, 9);
  const NearestVertexIndex index(body);
  const NearestBody all = index.query(q);
  const float bound = 0.08f;
  const NearestBody near = index.query_within(q, bound);
  int inside = 0;
  for (int i = 0; i < q.rows(); ++i) {
    if (all.distance[i] <= bound) {
      ++inside;
      EXPECT_EQ(near.index[i], all.index[i]) << i;
      EXPECT_EQ(near.distance[i], all.distance[i]) << i;
    } else {
      EXPECT_TRUE(std::isinf(near.distance[i])) << i << " at " << all.distance[i];
    }
  }
  EXPECT_GT(inside, 100);               // both branches are exercised
  EXPECT_GT(q.rows() - inside, 100);
  // A query at exactly the bound from a lone point: found, at that distance.
  Points one(1, 3), at(1, 3);
  one << 0.f, 0.f, 0.f;
  at << 0.25f, 0.f, 0.f;  // exact in float, as is its square
  const NearestBody edge = NearestVertexIndex(one).query_within(at, 0.25f);
  EXPECT_EQ(edge.index[0], 0);
  EXPECT_EQ(edge.distance[0], 0.25f);
  EXPECT_TRUE(std::isinf(NearestVertexIndex(one).query_within(at, 0.2499f).distance[0]));
}

// A thread's guesses (its last answers for as many queries against as many points) prune the walk
// but never change the answer: it is what a thread without guesses gives, for guesses near and far,
// bounded or not, with ties between duplicated points, on one thread and on the threads.
TEST(NearestBody, GuessesFromTheLastAnswerChangeNoAnswer) {
  Points body = random_points(2000, 1.f, 11);
  body.bottomRows(200) = body.topRows(200);  // 200 points twice: ties
  const NearestVertexIndex index(body);
  auto without_guesses = [&](const Points& q, float bound) {
    NearestBody answer;
    std::thread fresh([&] { answer = index.query_within(q, bound); });  // a new thread has no guesses
    fresh.join();
    return answer;
  };
  for (const int rows : {300, 3000}) {
    const Points far = random_points(rows, 1.5f, 12);
    Points near = far + 0.01f * random_points(rows, 1.f, 13);
    for (int i = 0; i < 100; ++i) near.row(i) = body.row(1900 + i % 100);  // exactly on a duplicated point
    for (const float bound : {std::numeric_limits<float>::infinity(), 0.08f}) {
      // The guesses: from far for near, from near for far.
      for (const Points* q : std::initializer_list<const Points*>{&far, &near, &far}) {
        const NearestBody guessed = index.query_within(*q, bound), fresh = without_guesses(*q, bound);
        EXPECT_EQ(guessed.index, fresh.index) << rows << " rows, bound " << bound;
        EXPECT_EQ(guessed.distance, fresh.distance) << rows << " rows, bound " << bound;
      }
    }
  }
}

// A kept index is handed out again for the same points (by value, not by address), a new one for
// other points, and either answers as a fresh build does.
TEST(NearestBody, KeptIndexIsTheSameForTheSamePointsOnly) {
  const Points body = random_points(2000, 1.f, 7), q = random_points(300, 1.5f, 8);
  const auto first = NearestVertexIndex::kept(body);
  const Points copy = body;
  EXPECT_EQ(NearestVertexIndex::kept(copy), first);
  Points moved = body;
  moved(1234, 2) += 1e-3f;
  const auto other = NearestVertexIndex::kept(moved);
  EXPECT_NE(other, first);
  EXPECT_EQ(NearestVertexIndex::kept(body), first);  // still kept beside the other
  const NearestBody fresh = nearest_body(q, moved), from_kept = other->query(q);
  EXPECT_EQ(from_kept.index, fresh.index);
  EXPECT_EQ(from_kept.distance, fresh.distance);
}

// query() hands a thread its last answer again only for the same index and the same points: an
// index made afresh at a freed one's address, or points moved by one coordinate, are asked anew.
TEST(NearestBody, RepeatedQueryAnswersOnlyForTheSameIndexAndPoints) {
  const Points body = random_points(2000, 1.f, 7), other_body = random_points(2000, 1.f, 11);
  Points q = random_points(300, 1.5f, 8), moved = q;
  moved(17, 0) += 0.5f;
  // The expected answers first: nearest_body asks an index of its own, on this thread too.
  const NearestBody expected = nearest_body(q, other_body), expected_moved = nearest_body(moved, other_body);
  auto first = std::make_unique<NearestVertexIndex>(body);
  const NearestBody a = first->query(q);
  EXPECT_EQ(first->query(q).index, a.index);
  first.reset();
  const auto second = std::make_unique<NearestVertexIndex>(other_body);  // often at the same address
  const NearestBody b = second->query(q);
  EXPECT_EQ(b.index, expected.index);
  EXPECT_EQ(b.distance, expected.distance);
  const NearestBody c = second->query(moved);
  EXPECT_EQ(c.index, expected_moved.index);
  EXPECT_EQ(c.distance, expected_moved.distance);
}

}  // namespace
}  // namespace layersnet::dataset
