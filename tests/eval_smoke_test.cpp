#include <gtest/gtest.h>

#include "sdfprune/builtin.hpp"
#include "sdfprune/eval.hpp"

TEST(EvalSmoke, UnitSphere) {
    const sdfprune::Scene sc = sdfprune::builtin_scene("sphere");
    EXPECT_FLOAT_EQ(sdfprune::eval_point(sc, {2, 0, 0}), 1.0f);
    EXPECT_FLOAT_EQ(sdfprune::eval_point(sc, {0, 0, 0}), -1.0f);
}
