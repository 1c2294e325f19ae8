// The tape's mechanics: arena reuse, no-record mode, accumulation, parameter table.
#include "autodiff/ops_dense.h"
#include "autodiff/params.h"
#include "gradcheck_registry.h"

#include <sys/resource.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <vector>

namespace layersnet::ad::testing {

// A step of fixed shape; returns the loss-free output so the test can run backward on it.
template <class T>
Var<T> some_step(Tape<T>& tape, ParamStore<T>& params, int rows) {
  std::vector<T> data(static_cast<std::size_t>(rows * 8), T(0.5));
  Var<T> x = tape.constant(data.data(), rows, 8);
  Var<T> y = x;
  for (int layer = 0; layer < 20; ++layer) y = add(tape, y, params.var(0));
  return y;
}

TEST(Arena, SteadyStateStepsMakeNoHeapAllocation) {
  Tape<float> tape(/*first_block_bytes=*/256);  // tiny first block: forces growth on step 1
  ParamStore<float> params;
  params.add("bias", 1, 8);
  params.finalize();
  std::size_t bytes_first = 0, heap_after_first = 0;
  for (int step = 0; step < 6; ++step) {
    tape.reset();
    Var<float> y = some_step(tape, params, 1000);
    std::fill_n(y.grad, y.size(), 1.0f);
    tape.backward_seeded();
    if (step == 0) {
      bytes_first = tape.arena().bytes_in_use();
      heap_after_first = tape.arena().heap_allocations();
      EXPECT_GT(heap_after_first, 1u) << "the test must start with a too-small arena";
    } else if (step >= 2) {
      // Step 1 merges the blocks of step 0 into one; from then on nothing new.
      EXPECT_EQ(tape.arena().bytes_in_use(), bytes_first);
      EXPECT_EQ(tape.arena().heap_allocations(), heap_after_first + 1);
      EXPECT_GE(tape.arena().capacity(), bytes_first);
    }
  }
}

long minor_page_faults() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_minflt;
}

// Writes one byte per 4 KiB page of a fresh buffer, then frees it.
void touch_and_free(std::size_t bytes) {
  auto* p = static_cast<char*>(std::malloc(bytes));
  ASSERT_NE(p, nullptr);
  volatile char* pages = p;
  for (std::size_t i = 0; i < bytes; i += 4096) pages[i] = 1;
  std::free(p);
}

TEST(Heap, AFreedBufferIsReusedWithoutPageFaults) {
#if !defined(__GLIBC__)
  GTEST_SKIP() << "the malloc tuning is glibc's";
#endif
  keep_freed_memory_in_process();
  // Above glibc's largest mmap threshold (32 MiB): untuned, every such buffer is a fresh mmap,
  // 16,384 faults of 4 KiB.
  constexpr std::size_t kBytes = std::size_t{64} << 20;
  touch_and_free(kBytes);
  const long before = minor_page_faults();
  touch_and_free(kBytes);
  EXPECT_LT(minor_page_faults() - before, 64);
}

TEST(Arena, AllocationsAreAlignedAndDistinct) {
  Arena arena(128);
  std::set<void*> seen;
  for (int k = 0; k < 100; ++k) {
    void* p = arena.allocate(static_cast<std::size_t>(k * 7));
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(p) % Arena::kAlignment, 0u);
    EXPECT_TRUE(seen.insert(p).second);
  }
  arena.rewind();
  EXPECT_EQ(arena.bytes_in_use(), 0u);
}

TEST(Tape, NoRecordMakesNoNodesAndNoGradients) {
  Tape<double> tape;
  const RowMat<double> a = random_matrix(3, 4, 1), b = random_matrix(3, 4, 2);
  Var<double> va = tape.leaf(a.data(), 3, 4);
  {
    NoRecord<double> off(tape);
    Var<double> vb = tape.leaf(b.data(), 3, 4);
    EXPECT_EQ(vb.grad, nullptr);
    Var<double> y = add(tape, va, vb);
    EXPECT_EQ(y.grad, nullptr);
    EXPECT_TRUE(tape.nodes().empty());
    EXPECT_TRUE(y.val().isApprox(a + b));
  }
  EXPECT_TRUE(tape.recording());
  Var<double> y = add(tape, va, va);
  EXPECT_EQ(tape.nodes().size(), 1u);
  EXPECT_NE(y.grad, nullptr);
}

TEST(Tape, ConstantsGetNoGradientAndStopRecording) {
  Tape<double> tape;
  const RowMat<double> a = random_matrix(2, 2, 3);
  Var<double> c1 = tape.constant(a.data(), 2, 2), c2 = tape.constant(a.data(), 2, 2);
  Var<double> y = add(tape, c1, c2);
  EXPECT_EQ(y.grad, nullptr);
  EXPECT_TRUE(tape.nodes().empty());
}

TEST(Tape, BackwardAccumulatesWhenAVariableIsUsedTwice) {
  Tape<double> tape;
  const RowMat<double> a = random_matrix(2, 3, 4);
  Var<double> x = tape.leaf(a.data(), 2, 3);
  Var<double> y = add(tape, x, x);  // dy/dx = 2
  std::fill_n(y.grad, y.size(), 1.0);
  tape.backward_seeded();
  for (int64_t k = 0; k < x.size(); ++k) EXPECT_EQ(x.grad[k], 2.0);
}

// Gradients of op outputs live in the tape's GradRegion and are given back behind the backward
// walk: after backward an intermediate gradient reads zero again, leaves keep theirs, and a
// second step on the same tape gives the same gradients (the region starts from zero pages).
TEST(Tape, IntermediateGradientsAreReleasedAndLeavesKept) {
  Tape<float> tape;
  std::vector<float> a(1 << 20);  // 4 MiB per tensor: spans whole 2 MiB pages of the region
  for (std::size_t k = 0; k < a.size(); ++k) a[k] = static_cast<float>(k % 7) - 3.f;
  std::vector<float> first;
  for (int step = 0; step < 2; ++step) {
    tape.reset();
    Var<float> x = tape.leaf(a.data(), 1024, 1024);
    Var<float> h = mul(tape, x, x);     // intermediate
    Var<float> y = add(tape, h, x);     // dy/dx = 2x + 1
    Var<float> loss = sum_all(tape, y);
    ASSERT_NE(h.grad, nullptr);
    EXPECT_GE(tape.grad_region().top(), 2 * a.size() * sizeof(float));  // h and y gradients
    tape.backward(loss);
    for (std::size_t k = 0; k < a.size(); k += 4099) EXPECT_EQ(x.grad[k], 2.f * a[k] + 1.f) << k;
    for (std::size_t k = 0; k < a.size(); k += 4099) EXPECT_EQ(h.grad[k], 0.f) << "released: reads zero";
    if (step == 0) first.assign(x.grad, x.grad + x.size());
    else EXPECT_TRUE(std::equal(first.begin(), first.end(), x.grad));
  }
}

// bench model --profile: every recorded op reports its kind, time and bytes; a profiled
// no-record forward reports its ops too, with no node and no gradient.
TEST(Tape, ProfileCountsOpsOfRecordedAndUnrecordedForwards) {
  Tape<double> tape;
  const RowMat<double> a = random_matrix(64, 8, 6);
  TapeProfile rec, inf;
  tape.set_profile(&rec);
  Var<double> x = tape.leaf(a.data(), 64, 8);
  Var<double> loss = sum_all(tape, mul(tape, x, x));
  tape.backward(loss);
  tape.set_profile(nullptr);
  EXPECT_EQ(rec.ops[static_cast<std::size_t>(OpKind::Mul)].count, 1);
  EXPECT_EQ(rec.ops[static_cast<std::size_t>(OpKind::SumAll)].count, 1);
  EXPECT_EQ(rec.ops[static_cast<std::size_t>(OpKind::Mul)].grad_bytes, 64u * 8u * sizeof(double));
  EXPECT_GE(rec.ops[static_cast<std::size_t>(OpKind::Mul)].arena_bytes, 64u * 8u * sizeof(double));
  EXPECT_GE(rec.ops[static_cast<std::size_t>(OpKind::Mul)].backward_ms, 0.0);
  tape.reset();
  NoRecord<double> off(tape);
  tape.set_profile(&inf);
  Var<double> c = tape.constant(a.data(), 64, 8);
  Var<double> y = sum_all(tape, mul(tape, c, c));
  tape.set_profile(nullptr);
  EXPECT_EQ(inf.ops[static_cast<std::size_t>(OpKind::Mul)].count, 1);
  EXPECT_EQ(inf.ops[static_cast<std::size_t>(OpKind::SumAll)].count, 1);
  EXPECT_EQ(inf.ops[static_cast<std::size_t>(OpKind::Mul)].grad_bytes, 0u);
  EXPECT_EQ(y.grad, nullptr);
  EXPECT_TRUE(tape.nodes().empty());
  EXPECT_NEAR(y.scalar(), a.squaredNorm(), 1e-12 * a.squaredNorm());
}

TEST(Tape, BackwardNeedsAScalarLoss) {
  Tape<double> tape;
  const RowMat<double> a = random_matrix(2, 3, 5);
  Var<double> x = tape.leaf(a.data(), 2, 3);
  Var<double> y = add(tape, x, x);
  EXPECT_THROW(tape.backward(y), CheckError);
}

TEST(ParamStore, NameTableAndFlatBuffers) {
  ParamStore<float> params;
  const int q = params.add("encoder.layers.0.attn.q_proj.weight", 128, 128);
  const int b = params.add("encoder.layers.0.attn.q_proj.bias", 1, 128);
  params.finalize();
  EXPECT_EQ(params.index_of("encoder.layers.0.attn.q_proj.bias"), b);
  EXPECT_EQ(params.entries()[static_cast<std::size_t>(q)].rows, 128);
  EXPECT_GE(params.total_size(), 128u * 128u + 128u);
  Var<float> vb = params.var(b);
  EXPECT_EQ(vb.value, params.values().data() + params.entries()[static_cast<std::size_t>(b)].offset);
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(vb.value) % 4, 0u);
  try {
    params.index_of("encoder.layers.0.attn.q_proj.wieght");
    FAIL() << "unknown name accepted";
  } catch (const CheckError& e) {
    EXPECT_NE(std::string(e.what()).find("closest: 'encoder.layers.0.attn.q_proj."), std::string::npos) << e.what();
  }
  EXPECT_THROW(params.add("late", 1, 1), CheckError);
}

// A program with a tape gets the 64-byte aligned operator new (autodiff/aligned_new.cpp): with
// malloc's 16-byte alignment, Eigen's reductions would sum in an address-dependent order and the
// last bits of a result would depend on the heap's history.
TEST(AlignedHeap, EveryBufferStartsOnACacheLine) {
  std::vector<std::unique_ptr<std::vector<float>>> keep;  // live together: distinct addresses
  for (std::size_t n : {1u, 3u, 5u, 17u, 33u, 101u, 1001u, 4099u}) {
    keep.push_back(std::make_unique<std::vector<float>>(n, 1.f));
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(keep.back()->data()) % 64, 0u) << n << " floats";
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(keep.back().get()) % 64, 0u);
  }
}

}  // namespace layersnet::ad::testing
