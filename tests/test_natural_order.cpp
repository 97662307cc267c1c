#include "tools/natural_order.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

namespace laserline::tools {
namespace {

std::vector<std::string> sorted(std::vector<std::string> names) {
  std::sort(names.begin(), names.end(), natural_less);
  return names;
}

TEST(NaturalOrder, NumbersCompareAsNumbers) {
  std::vector<std::string> names;
  for (int k = 320; k >= 1; --k)
    names.push_back("step_num" + std::to_string(k) + ".png");
  std::vector<std::string> alphabetical = names;
  std::sort(alphabetical.begin(), alphabetical.end());
  ASSERT_EQ(alphabetical[1], "step_num10.png") << "the order the issue reported";
  const std::vector<std::string> natural = sorted(names);
  for (int k = 1; k <= 320; ++k)
    EXPECT_EQ(natural[static_cast<std::size_t>(k - 1)], "step_num" + std::to_string(k) + ".png");

  EXPECT_EQ(sorted({"b10a2", "b2a10", "b2a9", "b10a1"}),
            (std::vector<std::string>{"b2a9", "b2a10", "b10a1", "b10a2"}));
  EXPECT_EQ(sorted({"scan_12_b", "scan_12", "scan_12_a", "scan_2"}),
            (std::vector<std::string>{"scan_2", "scan_12", "scan_12_a", "scan_12_b"}));
  // Longer than any integer type: compared digit by digit.
  EXPECT_TRUE(natural_less("f99999999999999999999999", "f100000000000000000000000"));
  EXPECT_FALSE(natural_less("f100000000000000000000000", "f99999999999999999999999"));
}

TEST(NaturalOrder, LeadingZerosAndCase) {
  // Zero-padded and unpadded numbers interleave by value.
  EXPECT_EQ(sorted({"img010.png", "img9.png", "img0011.png", "img1.png"}),
            (std::vector<std::string>{"img1.png", "img9.png", "img010.png", "img0011.png"}));
  // Case does not separate names ("IMG_2" is not sent after every lower-case name).
  EXPECT_EQ(sorted({"img_3.png", "IMG_2.PNG", "Img_10.png", "img_1.png"}),
            (std::vector<std::string>{"img_1.png", "IMG_2.PNG", "img_3.png", "Img_10.png"}));
  // Names that differ only in padding or case still have one order, whatever the input order.
  EXPECT_EQ(sorted({"a1", "A1", "a01"}), sorted({"a01", "A1", "a1"}));
  EXPECT_TRUE(natural_less("a01", "a1") != natural_less("a1", "a01"));
  EXPECT_TRUE(natural_less("a", "a0"));
  EXPECT_TRUE(natural_less("a0", "a00"));
}

// std::sort needs a strict weak order: irreflexive, asymmetric, transitive, and so is
// equivalence (here: only equal strings are equivalent).
TEST(NaturalOrder, IsAStrictTotalOrder) {
  const std::vector<std::string> names = {
      "",    "0",    "00",  "1",   "01", "10",  "9",     "a",     "A",      "a0",      "a00",
      "a1",  "a01",  "A1",  "a10", "a9", "a_1", "a-1",   "a.png", "a1.png", "a10.png", "a2.png",
      "a1b", "a01b", "a1B", "b",   "_",  "~",   "z9z10", "z10z9", "Z9z9",   "\xc3\xa9"};
  for (const auto& a : names) {
    EXPECT_FALSE(natural_less(a, a)) << a;
    for (const auto& b : names) {
      if (a != b) {
        EXPECT_NE(natural_less(a, b), natural_less(b, a)) << a << " " << b;
      }
      for (const auto& c : names) {
        if (natural_less(a, b) && natural_less(b, c)) {
          EXPECT_TRUE(natural_less(a, c)) << a << " < " << b << " < " << c;
        }
      }
    }
  }
}

}  // namespace
}  // namespace laserline::tools
