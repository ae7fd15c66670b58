// The results folder: jobs listed newest first, state written atomically, a job left running
// by a dead daemon shown as interrupted (never done), bad folders and ids refused by name.
#include "insitu/daemon/results.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace insitu::daemon {
namespace {

namespace fs = std::filesystem;

fs::path Fresh(const char* name) {
  const fs::path d = fs::temp_directory_path() / name;
  fs::remove_all(d);
  return d;
}

TEST(Results, JobsAreListedAndKeptAcrossARestart) {
  const fs::path dir = Fresh("insitu_results_test");
  std::string done_id, running_id;
  {
    auto store = ResultsStore::Open(dir.string());
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    auto a = store->Begin("scan");
    ASSERT_TRUE(a.ok());
    ASSERT_TRUE(store->Finish(a->id, "done", "").ok());
    done_id = a->id;
    auto b = store->Begin("mark");
    ASSERT_TRUE(b.ok());
    running_id = b->id;
    EXPECT_GT(running_id, done_id);  // sortable, newest last
    const auto list = store->List();
    ASSERT_EQ(list.size(), 2u);
    EXPECT_EQ(list[0].id, running_id);  // newest first
    EXPECT_EQ(list[0].status, "running");
    EXPECT_EQ(list[1].status, "done");
    EXPECT_FALSE(fs::exists(fs::path(list[0].dir) / "state.json.tmp"));
    // The daemon dies here, the mark job still running.
  }
  auto reopened = ResultsStore::Open(dir.string());
  ASSERT_TRUE(reopened.ok());
  EXPECT_EQ(reopened->interrupted_at_open(), 1);
  auto done = reopened->Get(done_id);
  ASSERT_TRUE(done.ok());
  EXPECT_EQ(done->status, "done");
  auto interrupted = reopened->Get(running_id);
  ASSERT_TRUE(interrupted.ok());
  EXPECT_EQ(interrupted->status, "interrupted");
  EXPECT_EQ(interrupted->job, "mark");
  // A new job after the restart does not reuse an id.
  auto c = reopened->Begin("scan");
  ASSERT_TRUE(c.ok());
  EXPECT_NE(c->id, done_id);
  EXPECT_NE(c->id, running_id);
}

TEST(Results, BadStateIdsAndStatusesAreNamed) {
  const fs::path dir = Fresh("insitu_results_bad");
  auto store = ResultsStore::Open(dir.string());
  ASSERT_TRUE(store.ok());
  fs::create_directories(dir / "garbage");
  std::ofstream(dir / "garbage" / "state.json") << "{not json";
  const auto list = store->List();
  ASSERT_EQ(list.size(), 1u);
  EXPECT_EQ(list[0].status, "unreadable");
  EXPECT_EQ(store->Get("../etc").status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store->Get("nope").status().code(), StatusCode::kNotFound);
  auto a = store->Begin("scan");
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(store->Finish(a->id, "great", "").code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store->Finish("nope", "done", "").code(), StatusCode::kNotFound);
  // A results folder that cannot be made: a file stands where it should be.
  const fs::path file = Fresh("insitu_results_file");
  std::ofstream(file) << "x";
  EXPECT_EQ(ResultsStore::Open(file.string()).status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace insitu::daemon
