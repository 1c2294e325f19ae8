// The stress report's verdicts and JSON (the runs themselves: test_extremes.cpp).
#include "eval/stress_report.h"

#include <gtest/gtest.h>

namespace layersnet::eval {
namespace {

TEST(StressReport, VerdictNamesWhatBrokeAndJsonAgrees) {
  StressResult r;
  r.label = "wind 2000";
  r.frames = 3;
  r.strain_limit = 1.5;
  EXPECT_EQ(stress_verdict(r), "ok");
  r.max_bound_ratio = 1.2;
  r.first_bad_frame = 1;
  EXPECT_EQ(stress_verdict(r), "FAIL: distance");
  r.first_torn_frame = 2;
  EXPECT_EQ(stress_verdict(r), "FAIL: distance, strain");
  r.finite = false;
  EXPECT_EQ(stress_verdict(r), "FAIL: non-finite");
  const nlohmann::json j = stress_result_json(r);
  EXPECT_EQ(j["label"], "wind 2000");
  EXPECT_FALSE(j["passed"].get<bool>());
  EXPECT_FALSE(j["within_bound"].get<bool>());
  EXPECT_FALSE(j["within_strain"].get<bool>());
  EXPECT_EQ(j["first_torn_frame"], 2);
  EXPECT_EQ(j["strain_limit"], 1.5);
  EXPECT_TRUE(j["per_frame"].contains("strain_p99"));
}

}  // namespace
}  // namespace layersnet::eval
