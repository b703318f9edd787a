// report.html (jobs/html_report.h, issue 24 part 4): a job writes the page of its summary with a row per scan, an
// embedded thumbnail that is a real picture of the decoded container, and links to heat maps that exist; names are
// escaped; a real browser (headless Chromium, when installed) runs the page's sorting and draws it; bad summaries
// and options fail naming the file or the key.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "engine/shapes.h"
#include "jobs/config.h"
#include "jobs/container_file.h"
#include "jobs/html_report.h"
#include "jobs/stream_decode.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs_util.h"
#include "png_util.h"

namespace scanpress {
namespace {

namespace fs = std::filesystem;

using testing::readText;
using testing::unbase64;

size_t count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

// Pixels that are not the page's white or the thumbnail's flat background: drawn content.
size_t inked(const Image& img) {
  size_t n = 0;
  for (size_t i = 0; i + 2 < img.rgb.size(); i += 3) {
    const int r = img.rgb[i], g = img.rgb[i + 1], b = img.rgb[i + 2];
    n += !(r > 235 && g > 235 && b > 235) && !(r == g && g == b && r > 200);
  }
  return n;
}

// A job over two small scans (one with a name full of HTML) and a broken file, measured and rendered.
struct Batch {
  testing::TempDir dir;
  std::string out, weird = "a <b>&\"x\".ply";
  nlohmann::json summary;
  Batch() {
    fs::create_directories(dir.file("in"));
    EXPECT_TRUE(writePly(dir.file("in/" + weird), icosphere(3)).isOk());
    Mesh egg = icosphere(4);
    for (auto& v : egg.positions) v[1] *= 2;
    EXPECT_TRUE(writePly(dir.file("in/egg.ply"), egg).isOk());
    testing::writeBytes(dir.file("in/broken.ply"), "ply\nformat ascii 1.0\nelement vertex 9\nend_header\n1 2\n");
    testing::writeBytes(dir.file("job.json"),
                        R"({"inputs": ["in"], "output": {"directory": "out", "html": "report.html"},
      "measure": {"enabled": true, "render": true, "render_size": [160, 120]}})");
    out = dir.file("out");
    std::string log;
    EXPECT_EQ(testing::runScanpress("run '" + dir.file("job.json") + "' --quiet", &log), 2) << log;
    summary = nlohmann::json::parse(readText(out + "/summary.json"));
  }
};

// The src of every element of class `cls` (class="cls" ... src="..."), in page order, with `prefix` removed (an
// element whose src does not start with it is skipped). Plain search: std::regex recurses once per character and
// overflows the stack on a base64 picture under the sanitizers.
std::vector<std::string> sources(const std::string& html, const std::string& cls, const std::string& prefix) {
  std::vector<std::string> out;
  const std::string mark = "class=\"" + cls + "\"";
  for (size_t at = html.find(mark); at != std::string::npos; at = html.find(mark, at + 1)) {
    const size_t close = html.find('>', at), src = html.find("src=\"", at);
    if (src == std::string::npos || src > close) continue;
    const size_t begin = src + 5, end = html.find('"', begin);
    if (end == std::string::npos) break;
    const std::string value = html.substr(begin, end - begin);
    if (value.rfind(prefix, 0) == 0) out.push_back(value.substr(prefix.size()));
  }
  return out;
}

// Thumbnails of every scan's picture, in row order.
std::vector<Image> thumbnails(const std::string& html) {
  std::vector<Image> out;
  for (const std::string& data : sources(html, "thumb", "data:image/png;base64,"))
    out.push_back(testing::decodePng(unbase64(data)));
  return out;
}

TEST(HtmlReport, AJobWritesAPageWithEveryScan) {
  Batch b;
  const std::string html = readText(b.out + "/report.html");
  EXPECT_EQ(count(html, "<tr class=\"scan"), 3u);
  EXPECT_EQ(count(html, "<tr class=\"scan failed\""), 1u);
  // The weird name is escaped, never markup.
  EXPECT_EQ(html.find("<b>&"), std::string::npos);
  EXPECT_NE(html.find("a &lt;b&gt;&amp;&quot;x&quot;.ply"), std::string::npos);
  // Every thumbnail is a real picture: a PNG of the thumbnail's size with the model drawn on it.
  const std::vector<Image> thumbs = thumbnails(html);
  for (const Image& img : thumbs) {
    EXPECT_EQ(img.width, 240);
    EXPECT_EQ(img.height, 180);
    EXPECT_GT(inked(img), 2000u);  // a sphere or an egg filling most of 240x180 is far more
  }
  EXPECT_EQ(thumbs.size(), 2u);
  // Every heat map link resolves, relative to the page, to the picture the job wrote.
  const std::vector<std::string> heat_urls = sources(html, "heat", "");
  const size_t heats = heat_urls.size();
  for (const std::string& url : heat_urls) {
    std::string path;
    for (size_t i = 0; i < url.size(); ++i)
      if (url[i] == '%' && i + 2 < url.size()) {
        path += static_cast<char>(std::stoi(url.substr(i + 1, 2), nullptr, 16));
        i += 2;
      } else {
        path += url[i];
      }
    EXPECT_TRUE(fs::exists(b.out + "/" + path)) << path;
  }
  EXPECT_EQ(heats, 2u);
  // The numbers are the summary's.
  for (const auto& f : b.summary["files"]) {
    if (!f.contains("bpv")) continue;
    char bpv[32];
    std::snprintf(bpv, sizeof bpv, "%.2f", f["bpv"].get<double>());
    EXPECT_NE(html.find(std::string(">") + bpv + "<"), std::string::npos) << bpv;
    EXPECT_TRUE(f.contains("picture"));
  }
}

TEST(HtmlReport, AScanOverTheMemoryBudgetIsDrawnFromAClusteredDecode) {
  Batch b;
  // 1.25 MiB: the egg's whole decode (about 1.45 MB estimated) is over it, the small sphere's is not.
  HtmlReportOptions options;
  options.memory_budget = 1280 << 10;
  ASSERT_TRUE(writeHtmlReport(b.out + "/summary.json", b.out + "/small.html", options).isOk());
  const auto clustered = thumbnails(readText(b.out + "/small.html"));
  const auto whole = thumbnails(readText(b.out + "/report.html"));
  ASSERT_EQ(clustered.size(), 2u);
  ASSERT_EQ(whole.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    // The same shape: as much drawn, within 5%.
    EXPECT_GT(inked(clustered[i]), 2000u);
    EXPECT_NEAR(double(inked(clustered[i])), double(inked(whole[i])), 0.05 * inked(whole[i])) << i;
  }
  // The egg's picture comes from the clustered decode (its whole decode is over the budget), the sphere's from the
  // whole one; at 120 cells per axis each of the egg's vertices is a cluster of its own, so the pictures agree.
  auto estimate = [&](const std::string& name) {
    auto file = ContainerFile::open(b.out + "/" + name);
    EXPECT_TRUE(file.isOk());
    std::vector<const TileEntry*> tiles;
    for (const TileEntry& e : file->tiles()) tiles.push_back(&e);
    return inMemoryDecodeBytes(tiles);
  };
  EXPECT_GT(estimate("egg.spz"), options.memory_budget);
  EXPECT_LT(estimate(std::string(b.weird).replace(b.weird.size() - 4, 4, ".spz")), options.memory_budget);
  EXPECT_EQ(readText(b.out + "/small.html").find("not decodable"), std::string::npos);
  std::string log;
  EXPECT_EQ(testing::runScanpress("report '" + b.out + "' --memory-budget 1M", &log), 1) << log;
  EXPECT_NE(log.find("--memory-budget: must be 0 or at least 16M"), std::string::npos) << log;
}

TEST(HtmlReport, RendersAndSortsInHeadlessChromium) {
  std::string browser;
  for (const char* name : {"chromium", "chromium-browser", "google-chrome"})
    if (std::system((std::string("command -v ") + name + " >/dev/null 2>&1").c_str()) == 0) {
      browser = name;
      break;
    }
  if (browser.empty()) GTEST_SKIP() << "no chromium (scripts/install-test-tools.sh installs Debian's): not rendered";
  Batch b;
  testing::TempDir profile;
  const std::string flags = " --headless --no-sandbox --disable-gpu --hide-scrollbars --user-data-dir='" +
                            profile.path() + "' --window-size=1400,900 ";
  const std::string url = "'file://" + b.out + "/report.html#sort=-bpv'";
  // The DOM after the page's script ran: the rows sorted by bits per vertex, descending (the failed file last).
  FILE* p = ::popen(("timeout 120 " + browser + flags + "--dump-dom " + url + " 2>/dev/null").c_str(), "r");
  std::string dom;
  char buf[4096];
  for (size_t n; (n = std::fread(buf, 1, sizeof buf, p)) > 0;) dom.append(buf, n);
  ::pclose(p);
  ASSERT_EQ(count(dom, "<tr class=\"scan"), 3u) << dom.substr(0, 500);
  EXPECT_EQ(count(dom, "class=\"thumb\""), 2u);
  std::vector<double> expected;
  for (const auto& f : b.summary["files"]) expected.push_back(f.value("bpv", -1.0));
  std::sort(expected.rbegin(), expected.rend());
  std::vector<double> shown;  // the first numeric cell after each row start is the input size; bpv is the third
  for (size_t at = dom.find("<tr class=\"scan"); at != std::string::npos; at = dom.find("<tr class=\"scan", at + 1)) {
    size_t c = at;
    for (int k = 0; k < 3; ++k) c = dom.find("<td class=\"n\" data-v=\"", c + 1);
    shown.push_back(std::stod(dom.substr(c + 22, dom.find('"', c + 22) - c - 22)));
  }
  ASSERT_EQ(shown.size(), expected.size());
  for (size_t i = 0; i < shown.size(); ++i) EXPECT_NEAR(shown[i], expected[i], 1e-9) << "row " << i;
  EXPECT_NE(dom.find("sorted-desc"), std::string::npos);
  // A screenshot: the page draws (the table, the thumbnails and the heat maps are pixels, not blanks).
  const std::string shot = profile.file("shot.png");
  ASSERT_EQ(std::system(("timeout 120 " + browser + flags + "--screenshot='" + shot + "' " + url + " >/dev/null 2>&1")
                            .c_str()),
            0);
  const Image img = testing::decodePng(testing::readBytes(shot));
  ASSERT_EQ(img.width, 1400);
  EXPECT_GT(inked(img), 20000u);
}

TEST(HtmlReport, BadSummariesAndOptionsFailNamingTheFileOrKey) {
  testing::TempDir dir;
  std::string out;
  EXPECT_NE(testing::runScanpress("report '" + dir.file("nowhere") + "'", &out), 0);
  EXPECT_NE(out.find(dir.file("nowhere")), std::string::npos) << out;
  testing::writeBytes(dir.file("summary.json"), "{\"files\": 3");
  EXPECT_NE(testing::runScanpress("report '" + dir.path() + "'", &out), 0);
  EXPECT_NE(out.find(dir.file("summary.json")), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir.file("report.html")));
  testing::writeBytes(dir.file("summary.json"), "{\"files\": []}");
  EXPECT_NE(testing::runScanpress("report '" + dir.path() + "' --out '" + dir.file("r.png") + "'", &out), 0);
  EXPECT_NE(out.find("--out"), std::string::npos) << out;
  EXPECT_NE(testing::runScanpress("report '" + dir.path() + "' --out '" + dir.file("summary.json") + "'", &out), 0);
  EXPECT_EQ(testing::runScanpress("report '" + dir.path() + "'", &out), 0) << out;
  EXPECT_NE(readText(dir.file("report.html")).find("0 file(s)"), std::string::npos);
  for (const char* bad : {R"({"inputs": ["a.ply"], "output": {"html": "r.txt"}})",
                          R"({"inputs": ["a.ply"], "output": {"html": "{dir}/r.html"}})",
                          R"({"inputs": ["a.ply"], "output": {"html": "r.html", "summary": ""}})"}) {
    auto job = parseJobConfig(bad, "/x/j.json");
    ASSERT_FALSE(job.isOk()) << bad;
    EXPECT_NE(job.status().message().find("/output/html"), std::string::npos) << job.status().message();
  }
}

}  // namespace
}  // namespace scanpress
