// TLS and bearer tokens on the real daemon: plaintext clients refused by a TLS server, missing
// and wrong tokens refused, admin RPCs locked behind the admin token, health open to probes.
#include <thread>

#include <gtest/gtest.h>

#include "clients/cpp/client.h"
#include "core/demo/demo_repository.h"
#include "harness/daemon_process.h"
#include "tests/support/demo_fixture.h"
#include "tests/support/integration_support.h"
#include "tests/support/test_support.h"
#include "tests/support/tls_fixtures.h"

namespace animspace {
namespace {

using harness::DaemonProcess;
using testing::TempDir;
using testing::code_of;
using testing::wait_until_serving;

class SecurityTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string why_not;
    std::filesystem::create_directories(work_.path() / "tls");
    auto files = testing::make_tls_files(work_.path() / "tls", &why_not);
    if (!files) GTEST_SKIP() << "no TLS certificates: " << why_not;
    tls_ = *files;
    ASSERT_TRUE(testing::write_demo_repository(work_.path() / "repo").ok());
    testing::write_text_file(work_.path() / "users.tokens", "# render farm\nfarm-token-1\n\nartist-token-2\n");
    testing::write_text_file(work_.path() / "admins.tokens", "admin-token-9\n");
  }

  std::unique_ptr<DaemonProcess> start(std::vector<std::string> extra) {
    std::vector<std::string> args{"--model-repository", (work_.path() / "repo").string(), "--tls-cert",
                                  tls_.server_cert.string(), "--tls-key", tls_.server_key.string(),
                                  "--auth-token-file", (work_.path() / "users.tokens").string(),
                                  "--admin-token-file", (work_.path() / "admins.tokens").string()};
    args.insert(args.end(), extra.begin(), extra.end());
    return std::make_unique<DaemonProcess>(args, work_.path());
  }

  ClientOptions tls_options(const std::string& token) const {
    ClientOptions options;
    options.deadline = std::chrono::milliseconds(5000);
    options.tls = true;
    options.tls_root_certificates = testing::read_text(tls_.ca_cert);
    options.tls_server_name = "localhost";
    options.token = token;
    return options;
  }

  TempDir work_;
  testing::TlsFiles tls_;
};



TEST_F(SecurityTest, TlsAndTokensGuardEveryRpcButHealth) {
  auto daemon = start({});
  // Health needs no token (probes and load balancers), but it does need TLS.
  Client probe(daemon->address(), tls_options(""));
  EXPECT_TRUE(wait_until_serving(probe));

  ClientOptions plaintext;
  plaintext.deadline = std::chrono::milliseconds(3000);
  plaintext.token = "farm-token-1";
  Client insecure(daemon->address(), plaintext);
  EXPECT_EQ(code_of([&] { insecure.list_models(); }), grpc::StatusCode::UNAVAILABLE);

  Client anonymous(daemon->address(), tls_options(""));
  try {
    anonymous.list_models();
    ADD_FAILURE() << "a call without a token was served";
  } catch (const RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::UNAUTHENTICATED);
    EXPECT_NE(e.server_message().find("missing bearer token"), std::string::npos) << e.server_message();
  }
  Client stranger(daemon->address(), tls_options("farm-token-2"));
  EXPECT_EQ(code_of([&] { stranger.list_models(); }), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(code_of([&] { stranger.describe_key_points("arm-pmsc"); }), grpc::StatusCode::UNAUTHENTICATED);

  Client farm(daemon->address(), tls_options("artist-token-2"));
  EXPECT_EQ(farm.list_models().size(), 5u);
  EXPECT_GT(farm.describe_key_points("arm-pmsc").indices.size(), 0);
  // Admin RPCs need the admin token.
  v1::RetrainRequest retrain;
  retrain.mutable_model()->set_name("arm-pmsc");
  retrain.set_dry_run(true);
  try {
    farm.retrain(retrain, std::chrono::seconds(30));
    ADD_FAILURE() << "a user token retrained a model";
  } catch (const RpcError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::PERMISSION_DENIED);
    EXPECT_NE(e.server_message().find("TrainingService/Retrain is an admin RPC"), std::string::npos)
        << e.server_message();
  }
  EXPECT_EQ(code_of([&] { farm.unload_model("arm-pmsc"); }), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(code_of([&] { farm.load_model("arm-pmsc"); }), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(code_of([&] { farm.stats("", true); }), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(code_of([&] { farm.stats(); }), grpc::StatusCode::OK);

  Client admin(daemon->address(), tls_options("admin-token-9"));
  EXPECT_EQ(admin.retrain(retrain, std::chrono::seconds(60)).new_version(), 0u);
  EXPECT_EQ(code_of([&] { admin.unload_model("arm-cross-pmsc"); }), grpc::StatusCode::OK);
  // The model was still there for the user a moment ago: nothing was touched by refused calls.
  EXPECT_EQ(farm.list_models().size(), 4u);
}

TEST_F(SecurityTest, ClientCertificatesWhenTheServerRequiresThem) {
  auto daemon = start({"--tls-client-ca", tls_.ca_cert.string()});
  ClientOptions without = tls_options("farm-token-1");
  Client no_cert(daemon->address(), without);
  EXPECT_EQ(code_of([&] { no_cert.health(); }), grpc::StatusCode::UNAVAILABLE);

  ClientOptions with = without;
  with.tls_client_certificate = testing::read_text(tls_.client_cert);
  with.tls_client_key = testing::read_text(tls_.client_key);
  Client certified(daemon->address(), with);
  EXPECT_TRUE(wait_until_serving(certified));
  EXPECT_EQ(certified.list_models().size(), 5u);
}

TEST(SecurityStartup, AnEmptyTokenFileStopsTheDaemonWithAMessage) {
  TempDir work;
  testing::write_text_file(work.path() / "empty.tokens", "# nobody yet\n");
  ASSERT_TRUE(testing::write_demo_repository(work.path() / "repo").ok());
  try {
    DaemonProcess daemon({"--model-repository", (work.path() / "repo").string(), "--auth-token-file",
                          (work.path() / "empty.tokens").string()},
                         work.path(), std::chrono::seconds(20));
    EXPECT_NE(daemon.wait_for_exit(std::chrono::seconds(10)), 0);
    EXPECT_NE(daemon.log().find("--auth-token-file"), std::string::npos) << daemon.log();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("--auth-token-file"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace animspace
