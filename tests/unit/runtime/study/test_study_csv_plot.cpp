// CSV reading (quoting, errors with line numbers) and the SVG plot.
#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "proprio/study/csv.hpp"
#include "proprio/study/plot.hpp"

namespace proprio::study {
namespace {

TEST(Csv, ParsesQuotesCommentsAndNumbers) {
  auto t = parse_csv("# comment\nlevel,label,trials\r\n0.5,\"a, \"\"b\"\"\",10\n\n1.5, plain ,20\n", "x.csv");
  ASSERT_TRUE(t) << t.error().message;
  ASSERT_EQ(t->rows.size(), 2u);
  EXPECT_EQ(t->rows[0][1], "a, \"b\"");
  EXPECT_EQ(t->rows[1][1], "plain");
  EXPECT_EQ(t->lines[1], 5);
  EXPECT_DOUBLE_EQ(*t->number(1, 0), 1.5);
  EXPECT_EQ(*t->integer(1, 2), 20);
  EXPECT_EQ(csv_field("a, \"b\""), "\"a, \"\"b\"\"\"");
  EXPECT_EQ(csv_field("plain"), "plain");
}

TEST(Csv, ErrorsNameTheFileLineAndColumn) {
  auto ragged = parse_csv("a,b\n1,2\n3\n", "r.csv");
  ASSERT_FALSE(ragged);
  EXPECT_NE(ragged.error().message.find("r.csv:3"), std::string::npos) << ragged.error().message;
  auto t = parse_csv("level,n\nnan,3\n0.1,x\n", "n.csv");
  ASSERT_TRUE(t);
  auto nan = t->number(0, 0);
  ASSERT_FALSE(nan);
  EXPECT_NE(nan.error().message.find("n.csv:2"), std::string::npos);
  EXPECT_NE(nan.error().message.find("'level'"), std::string::npos);
  EXPECT_FALSE(t->integer(1, 1));
  auto missing = t->require_column("trials");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("level, n"), std::string::npos);
  EXPECT_FALSE(parse_csv("", "e.csv"));
  EXPECT_FALSE(parse_csv("a,b\n\"open,1\n", "q.csv"));
}

// Issue 23.6: a spreadsheet's UTF-8 byte-order mark became part of the first
// column's name, so "subject" was no longer recognised as the id column.
TEST(Csv, StripsAUtf8ByteOrderMark) {
  auto t = parse_csv("\xEF\xBB\xBFsubject,a\n1,2\n", "bom.csv");
  ASSERT_TRUE(t) << t.error().message;
  EXPECT_EQ(t->header[0], "subject");
  EXPECT_TRUE(t->column("subject"));
}

// Issue 23.5: `psychometric fit --data /dev/zero` aborted and a FIFO hung.
TEST(Csv, RefusesSpecialFilesWithAMessage) {
  auto zero = read_csv("/dev/zero");
  ASSERT_FALSE(zero);
  EXPECT_NE(zero.error().message.find("/dev/zero"), std::string::npos) << zero.error().message;
  const std::filesystem::path fifo =
      std::filesystem::temp_directory_path() / ("proprio_csv_fifo_" + std::to_string(::getpid()));
  std::filesystem::remove(fifo);
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  auto f = read_csv(fifo);  // no writer: a blocking open would hang here
  EXPECT_FALSE(f);
  std::filesystem::remove(fifo);
  auto dir = read_csv(std::filesystem::temp_directory_path());
  EXPECT_FALSE(dir);
  auto missing = read_csv("/nonexistent/x.csv");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().code, Errc::not_found);
}

TEST(PsychometricSvg, DrawsPointsSizedByTrialsAndTheThreshold) {
  PsychometricPlot plot;
  plot.title = "demo <1>";
  PsychometricCurve c;
  c.label = "no haptics";
  c.data = {{1, 5, 10}, {2, 14, 20}, {3, 38, 40}};
  c.fit = PsychometricFit{PsychometricModel::weibull, {2.0, 3.0, 0.5, 0.0}, 0, 0, 0};
  c.threshold = 2.0 * std::pow(std::log(2.0), 1.0 / 3.0);
  c.threshold_ci = ConfidenceInterval{1.6, 2.2};
  plot.curves.push_back(c);
  const std::string svg = psychometric_svg(plot);
  EXPECT_EQ(svg.rfind("<svg", 0), 0u);
  EXPECT_NE(svg.find("</svg>"), std::string::npos);
  EXPECT_NE(svg.find("demo &lt;1&gt;"), std::string::npos);
  // Three data points; the one with 40 trials has twice the radius of 10.
  EXPECT_NE(svg.find("r=\"4.5\""), std::string::npos);
  EXPECT_NE(svg.find("r=\"9.0\""), std::string::npos);
  EXPECT_NE(svg.find("<path d=\"M"), std::string::npos);
  EXPECT_NE(svg.find("thr 1.77"), std::string::npos);
}

}  // namespace
}  // namespace proprio::study
