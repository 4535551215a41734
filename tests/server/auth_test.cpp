#include "server/auth.h"

#include <grpcpp/generic/async_generic_service.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "grpc/health/v1/health.grpc.pb.h"
#include "tests/support/test_support.h"
#include "tests/support/tls_fixtures.h"

namespace animspace::server {
namespace {

using animspace::testing::TempDir;
using animspace::testing::TlsFiles;
using animspace::testing::write_text_file;
using Metadata = std::multimap<grpc::string_ref, grpc::string_ref>;

constexpr grpc::StatusCode OK = grpc::StatusCode::OK;
constexpr grpc::StatusCode UN = grpc::StatusCode::UNAUTHENTICATED;
constexpr grpc::StatusCode PD = grpc::StatusCode::PERMISSION_DENIED;

constexpr const char* kAdminRpc = "/animspace.v1.ModelService/LoadModel";

// Metadata with one "authorization" entry per value; the strings must outlive the map.
Metadata authorization(const std::vector<std::string>& values) {
  Metadata metadata;
  metadata.emplace("user-agent", "grpc-c++/1.51");
  for (const auto& value : values) metadata.emplace("authorization", value);
  return metadata;
}

// An Authenticator from token files holding `user` and `admin` (nullopt: flag unset).
Authenticator make_authenticator(const TempDir& dir, const std::optional<std::string>& user,
                                 const std::optional<std::string>& admin) {
  ServerOptions options;
  if (user) {
    options.auth_token_file = dir / "user.tokens";
    write_text_file(options.auth_token_file, *user);
  }
  if (admin) {
    options.admin_token_file = dir / "admin.tokens";
    write_text_file(options.admin_token_file, *admin);
  }
  auto authenticator = Authenticator::from_options(options);
  EXPECT_TRUE(authenticator.ok()) << (authenticator.ok() ? "" : authenticator.error().message);
  return authenticator.ok() ? *authenticator : Authenticator();
}

// ---------------------------------------------------------------------------------------------
// Token files

TEST(AuthTokenFile, TrimsWhitespaceAndSkipsBlankAndCommentLines) {
  TempDir dir;
  const auto authenticator =
      make_authenticator(dir, "# user tokens\n\n   alpha  \n\tbeta\r\n  # gamma\n#delta\n\n", std::nullopt);
  EXPECT_TRUE(authenticator.enabled());
  EXPECT_EQ(authenticator.user_token_count(), 2u);
  EXPECT_EQ(authenticator.admin_token_count(), 0u);
  for (const std::string accepted : {"Bearer alpha", "Bearer beta"}) {
    const std::vector<std::string> values{accepted};
    EXPECT_EQ(authenticator.check(authorization(values), Access::kUser, "/x/Y").error_code(), OK) << accepted;
  }
  // Comment lines are not tokens, with or without the '#'; nor is a token's trimmed whitespace.
  for (const std::string refused : {"Bearer #delta", "Bearer delta", "Bearer gamma", "Bearer alph"}) {
    const std::vector<std::string> values{refused};
    EXPECT_EQ(authenticator.check(authorization(values), Access::kUser, "/x/Y").error_code(), UN) << refused;
  }
}

TEST(AuthTokenFile, NoTokenFilesMeansAuthenticationDisabled) {
  const auto authenticator = Authenticator::from_options(ServerOptions{});
  ASSERT_TRUE(authenticator.ok());
  EXPECT_FALSE(authenticator->enabled());
  for (const Access access : {Access::kPublic, Access::kUser, Access::kAdmin}) {
    EXPECT_TRUE(authenticator->check(Metadata{}, access, kAdminRpc).ok());
  }
}

TEST(AuthTokenFile, FileWithoutTokensIsAnErrorNamingFlagAndPath) {
  TempDir dir;
  const std::pair<std::string, bool> cases[] = {{"", false}, {"\n  \n# only a comment\n", false},
                                                {"", true}, {"#\n\t\n", true}};
  for (const auto& [content, is_admin] : cases) {
    ServerOptions options;
    const auto path = dir / "tokens";
    write_text_file(path, content);
    (is_admin ? options.admin_token_file : options.auth_token_file) = path;
    const auto authenticator = Authenticator::from_options(options);
    ASSERT_FALSE(authenticator.ok());
    EXPECT_EQ(authenticator.error().code, ErrorCode::kInvalidArgument);
    const std::string& message = authenticator.error().message;
    EXPECT_NE(message.find(is_admin ? "--admin-token-file" : "--auth-token-file"), std::string::npos) << message;
    EXPECT_NE(message.find(path.string()), std::string::npos) << message;
    EXPECT_NE(message.find("no tokens"), std::string::npos) << message;
  }
}

TEST(AuthTokenFile, MissingFileIsNotFoundNamingFlagAndPath) {
  TempDir dir;
  ServerOptions options;
  options.admin_token_file = dir / "absent.tokens";
  const auto authenticator = Authenticator::from_options(options);
  ASSERT_FALSE(authenticator.ok());
  EXPECT_EQ(authenticator.error().code, ErrorCode::kNotFound);
  EXPECT_NE(authenticator.error().message.find("--admin-token-file"), std::string::npos);
  EXPECT_NE(authenticator.error().message.find(options.admin_token_file.string()), std::string::npos);
}

TEST(AuthTokenFile, DirectoryIsAnIoError) {
  TempDir dir;
  ServerOptions options;
  options.auth_token_file = dir.path();
  const auto authenticator = Authenticator::from_options(options);
  ASSERT_FALSE(authenticator.ok());
  EXPECT_EQ(authenticator.error().code, ErrorCode::kIo);
  EXPECT_NE(authenticator.error().message.find("--auth-token-file"), std::string::npos);
}

TEST(AuthTokenFile, TokenWithInnerSpaceIsRefusedByLineWithoutEchoingIt) {
  TempDir dir;
  ServerOptions options;
  options.auth_token_file = dir / "user.tokens";
  write_text_file(options.auth_token_file, "good-token\n# comment\nsecret part\n");
  const auto authenticator = Authenticator::from_options(options);
  ASSERT_FALSE(authenticator.ok());
  EXPECT_EQ(authenticator.error().code, ErrorCode::kInvalidArgument);
  const std::string& message = authenticator.error().message;
  EXPECT_NE(message.find("line 3"), std::string::npos) << message;
  EXPECT_EQ(message.find("secret"), std::string::npos) << message;
}

// ---------------------------------------------------------------------------------------------
// check()

// Each presented "authorization" metadata against each configuration and access level. Expected
// codes are worked out by hand from the rules in auth.h:
//   U  = user tokens {user-token-1} only
//   UA = user tokens {user-token-1} and admin tokens {admin-token-1}
//   A  = admin tokens {admin-token-1} only (kUser needs nothing; kAdmin needs admin-token-1)
struct CheckRow {
  const char* name;
  std::optional<std::string> authorization;  // nullopt: no "authorization" entry at all
  grpc::StatusCode u_user, u_admin, ua_user, ua_admin, a_user, a_admin;
};

const CheckRow kCheckTable[] = {
    // {name, authorization, U:kUser, U:kAdmin, UA:kUser, UA:kAdmin, A:kUser, A:kAdmin}
    {"no token", std::nullopt, UN, UN, UN, UN, OK, UN},
    {"wrong token", "Bearer nope", UN, UN, UN, UN, OK, UN},
    {"user token", "Bearer user-token-1", OK, OK, OK, PD, OK, UN},
    {"admin token", "Bearer admin-token-1", UN, UN, OK, OK, OK, OK},
    {"lowercase scheme, user", "bearer user-token-1", OK, OK, OK, PD, OK, UN},
    {"uppercase scheme, admin", "BEARER admin-token-1", UN, UN, OK, OK, OK, OK},
    {"Basic scheme", "Basic x", UN, UN, UN, UN, OK, UN},
    {"scheme without token", "Bearer ", UN, UN, UN, UN, OK, UN},
    {"scheme glued to token", "Beareruser-token-1", UN, UN, UN, UN, OK, UN},
    {"extra spaces", "Bearer   user-token-1  ", OK, OK, OK, PD, OK, UN},
    {"token prefix", "Bearer user-token-", UN, UN, UN, UN, OK, UN},
    {"token plus suffix", "Bearer user-token-12", UN, UN, UN, UN, OK, UN},
};

TEST(AuthCheck, TableOverTokensAccessLevelsAndConfigurations) {
  TempDir dir_u, dir_ua, dir_a;
  const auto u = make_authenticator(dir_u, "user-token-1\n", std::nullopt);
  const auto ua = make_authenticator(dir_ua, "user-token-1\n", "admin-token-1\n");
  const auto a = make_authenticator(dir_a, std::nullopt, "admin-token-1\n");
  for (const auto& row : kCheckTable) {
    std::vector<std::string> values;
    if (row.authorization) values.push_back(*row.authorization);
    const Metadata metadata = authorization(values);
    const std::pair<const Authenticator*, const char*> configs[] = {{&u, "U"}, {&ua, "UA"}, {&a, "A"}};
    for (const auto& [authenticator, config] : configs) {
      EXPECT_EQ(authenticator->check(metadata, Access::kPublic, kAdminRpc).error_code(), OK)
          << row.name << ", " << config << ", kPublic";
    }
    const std::tuple<const Authenticator*, const char*, Access, grpc::StatusCode> cells[] = {
        {&u, "U", Access::kUser, row.u_user},     {&u, "U", Access::kAdmin, row.u_admin},
        {&ua, "UA", Access::kUser, row.ua_user},  {&ua, "UA", Access::kAdmin, row.ua_admin},
        {&a, "A", Access::kUser, row.a_user},     {&a, "A", Access::kAdmin, row.a_admin},
    };
    for (const auto& [authenticator, config, access, expected] : cells) {
      EXPECT_EQ(authenticator->check(metadata, access, kAdminRpc).error_code(), expected)
          << row.name << ", " << config << ", " << (access == Access::kUser ? "kUser" : "kAdmin");
    }
  }
}

TEST(AuthCheck, MessagesNameTheProblemAndTheRpc) {
  TempDir dir;
  const auto authenticator = make_authenticator(dir, "user-token-1\n", "admin-token-1\n");
  const std::vector<std::string> none, wrong{"Bearer nope"}, user{"Bearer user-token-1"};
  EXPECT_EQ(authenticator.check(authorization(none), Access::kUser, kAdminRpc).error_message(),
            "missing bearer token in 'authorization' metadata");
  EXPECT_EQ(authenticator.check(authorization(wrong), Access::kUser, kAdminRpc).error_message(),
            "invalid bearer token");
  EXPECT_EQ(authenticator.check(authorization(user), Access::kAdmin, kAdminRpc).error_message(),
            std::string(kAdminRpc) + " is an admin RPC: it needs an admin token");
}

TEST(AuthCheck, MostPrivilegedOfSeveralAuthorizationEntriesCounts) {
  TempDir dir;
  const auto authenticator = make_authenticator(dir, "user-token-1\n", "admin-token-1\n");
  const std::vector<std::string> wrong_then_admin{"Bearer nope", "Bearer admin-token-1"};
  const std::vector<std::string> basic_then_user{"Basic x", "Bearer user-token-1"};
  EXPECT_TRUE(authenticator.check(authorization(wrong_then_admin), Access::kAdmin, kAdminRpc).ok());
  EXPECT_TRUE(authenticator.check(authorization(basic_then_user), Access::kUser, kAdminRpc).ok());
  EXPECT_EQ(authenticator.check(authorization(basic_then_user), Access::kAdmin, kAdminRpc).error_code(), PD);
}

TEST(AuthCheck, ConstantTimeCompareIsPlainEqualityOnValues) {
  EXPECT_TRUE(tokens_equal_constant_time("", ""));
  EXPECT_TRUE(tokens_equal_constant_time("abc123", "abc123"));
  EXPECT_FALSE(tokens_equal_constant_time("xbc123", "abc123"));  // first byte differs
  EXPECT_FALSE(tokens_equal_constant_time("abc124", "abc123"));  // last byte differs
  EXPECT_FALSE(tokens_equal_constant_time("abc12", "abc123"));   // prefix
  EXPECT_FALSE(tokens_equal_constant_time("abc123", ""));
  EXPECT_FALSE(tokens_equal_constant_time(std::string_view("a\0b", 3), std::string_view("a\0c", 3)));
}

// ---------------------------------------------------------------------------------------------
// make_server_credentials: configuration errors (no openssl needed)

constexpr const char* kFakeCertificate = "-----BEGIN CERTIFICATE-----\nMIIB\n-----END CERTIFICATE-----\n";
constexpr const char* kFakeKey = "-----BEGIN PRIVATE KEY-----\nMIGH\n-----END PRIVATE KEY-----\n";

Error credentials_error(const ServerOptions& options) {
  auto credentials = make_server_credentials(options);
  EXPECT_FALSE(credentials.ok());
  return credentials.ok() ? Error{} : credentials.error();
}

TEST(ServerCredentials, PlaintextWhenNoTlsFlags) {
  const ServerOptions options;
  EXPECT_FALSE(tls_enabled(options));
  auto credentials = make_server_credentials(options);
  ASSERT_TRUE(credentials.ok());
  EXPECT_NE(credentials->get(), nullptr);
}

TEST(ServerCredentials, CertWithoutKeyAndKeyWithoutCertAreErrors) {
  TempDir dir;
  write_text_file(dir / "cert.pem", kFakeCertificate);
  write_text_file(dir / "key.pem", kFakeKey);
  ServerOptions only_cert;
  only_cert.tls_cert = dir / "cert.pem";
  EXPECT_TRUE(tls_enabled(only_cert));
  Error error = credentials_error(only_cert);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "--tls-cert '" + only_cert.tls_cert.string() + "' given without --tls-key; TLS needs both");

  ServerOptions only_key;
  only_key.tls_key = dir / "key.pem";
  error = credentials_error(only_key);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(error.message, "--tls-key '" + only_key.tls_key.string() + "' given without --tls-cert; TLS needs both");

  ServerOptions only_client_ca;
  only_client_ca.tls_client_ca = dir / "cert.pem";
  error = credentials_error(only_client_ca);
  EXPECT_EQ(error.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(error.message.find("--tls-client-ca"), std::string::npos) << error.message;
}

TEST(ServerCredentials, FilesThatAreNotTheExpectedPemAreErrorsNamingTheFlag) {
  TempDir dir;
  write_text_file(dir / "cert.pem", kFakeCertificate);
  write_text_file(dir / "key.pem", kFakeKey);
  write_text_file(dir / "text.txt", "hello, not PEM\n");
  write_text_file(dir / "encrypted.pem",
                  "-----BEGIN ENCRYPTED PRIVATE KEY-----\nMIH\n-----END ENCRYPTED PRIVATE KEY-----\n");
  struct Case {
    const char* cert;
    const char* key;
    const char* client_ca;
    const char* flag;
  };
  const Case cases[] = {
      {"text.txt", "key.pem", "", "--tls-cert"},
      {"key.pem", "cert.pem", "", "--tls-cert"},  // cert and key swapped
      {"cert.pem", "text.txt", "", "--tls-key"},
      {"cert.pem", "cert.pem", "", "--tls-key"},
      {"cert.pem", "encrypted.pem", "", "--tls-key"},
      {"cert.pem", "key.pem", "text.txt", "--tls-client-ca"},
  };
  for (const auto& c : cases) {
    ServerOptions options;
    options.tls_cert = dir / c.cert;
    options.tls_key = dir / c.key;
    if (*c.client_ca) options.tls_client_ca = dir / c.client_ca;
    const Error error = credentials_error(options);
    EXPECT_EQ(error.code, ErrorCode::kInvalidArgument) << c.cert << " " << c.key << " " << c.client_ca;
    EXPECT_EQ(error.message.rfind(std::string(c.flag) + ": '", 0), 0u) << error.message;
  }
}

TEST(ServerCredentials, MissingFileIsNotFoundNamingFlagAndPath) {
  TempDir dir;
  write_text_file(dir / "cert.pem", kFakeCertificate);
  ServerOptions options;
  options.tls_cert = dir / "cert.pem";
  options.tls_key = dir / "absent.key";
  const Error error = credentials_error(options);
  EXPECT_EQ(error.code, ErrorCode::kNotFound);
  EXPECT_EQ(error.message, "--tls-key: '" + options.tls_key.string() + "' does not exist");
}

// Every method of this service checks bearer tokens as an RPC handler would; methods whose name
// ends in "Admin" are admin RPCs. An allowed call answers with one (empty) message.
class TokenCheckingService : public grpc::CallbackGenericService {
 public:
  explicit TokenCheckingService(const Authenticator& authenticator) : authenticator_(authenticator) {}

  grpc::ServerGenericBidiReactor* CreateReactor(grpc::GenericCallbackServerContext* context) override {
    const std::string& method = context->method();
    const bool admin = method.size() >= 5 && method.compare(method.size() - 5, 5, "Admin") == 0;
    return new Reactor(authenticator_.check(context->client_metadata(), admin ? Access::kAdmin : Access::kUser, method));
  }

 private:
  class Reactor : public grpc::ServerGenericBidiReactor {
   public:
    explicit Reactor(const grpc::Status& status) {
      if (status.ok()) {
        StartWriteAndFinish(&response_, grpc::WriteOptions(), status);
      } else {
        Finish(status);
      }
    }
    void OnDone() override { delete this; }

   private:
    grpc::ByteBuffer response_{nullptr, 0};
  };

  const Authenticator& authenticator_;
};

// ---------------------------------------------------------------------------------------------
// Real TLS round trips: an in-process server with gRPC's default health service.

class TlsRoundTrip : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    files_ = animspace::testing::make_tls_files(dir_->path(), &why_not_);
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    if (!files_) {
      if (!animspace::testing::openssl_available()) GTEST_SKIP() << why_not_;
      FAIL() << why_not_;
    }
  }

  struct RunningServer {
    std::unique_ptr<TokenCheckingService> open_service;  // outlives the server (declared first)
    std::unique_ptr<grpc::Server> server;
    int port = 0;
    RunningServer() = default;
    RunningServer(RunningServer&&) = default;
    ~RunningServer() {
      if (server) server->Shutdown(std::chrono::system_clock::now());
    }
  };

  static RunningServer start(const ServerOptions& options, grpc::CallbackGenericService* generic = nullptr) {
    RunningServer running;
    auto credentials = make_server_credentials(options);
    EXPECT_TRUE(credentials.ok()) << (credentials.ok() ? "" : credentials.error().message);
    if (!credentials.ok()) return running;
    grpc::EnableDefaultHealthCheckService(true);
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:0", *credentials, &running.port);
    // A server needs at least one service of its own besides the built-in health service (gRPC
    // refuses to start with no polled completion queue), as the daemon has.
    static const Authenticator no_tokens;
    if (!generic) {
      running.open_service = std::make_unique<TokenCheckingService>(no_tokens);
      generic = running.open_service.get();
    }
    builder.RegisterCallbackGenericService(generic);
    running.server = builder.BuildAndStart();
    EXPECT_NE(running.server, nullptr);
    EXPECT_NE(running.port, 0);
    return running;
  }

  static ServerOptions tls_options() {
    ServerOptions options;
    options.tls_cert = files_->server_cert;
    options.tls_key = files_->server_key;
    return options;
  }

  // Client TLS credentials trusting `ca`, optionally presenting a certificate.
  static std::shared_ptr<grpc::ChannelCredentials> tls_client(const std::filesystem::path& ca,
                                                              const std::filesystem::path& cert = {},
                                                              const std::filesystem::path& key = {}) {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = animspace::testing::read_text(ca);
    if (!cert.empty()) {
      ssl.pem_cert_chain = animspace::testing::read_text(cert);
      ssl.pem_private_key = animspace::testing::read_text(key);
    }
    return grpc::SslCredentials(ssl);
  }

  static std::shared_ptr<grpc::Channel> channel(int port, const std::shared_ptr<grpc::ChannelCredentials>& credentials,
                                                const std::string& target_name_override = "localhost") {
    grpc::ChannelArguments arguments;
    if (!target_name_override.empty()) arguments.SetSslTargetNameOverride(target_name_override);
    // A fresh connection per channel, so one test's handshake never serves another's call.
    arguments.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
    return grpc::CreateCustomChannel("127.0.0.1:" + std::to_string(port), credentials, arguments);
  }

  static grpc::Status health_check(const std::shared_ptr<grpc::Channel>& channel,
                                   grpc::health::v1::HealthCheckResponse* response) {
    auto stub = grpc::health::v1::Health::NewStub(channel);
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    return stub->Check(&context, grpc::health::v1::HealthCheckRequest(), response);
  }

  static void expect_serving(const std::shared_ptr<grpc::Channel>& channel) {
    grpc::health::v1::HealthCheckResponse response;
    const grpc::Status status = health_check(channel, &response);
    ASSERT_TRUE(status.ok()) << status.error_code() << ": " << status.error_message();
    EXPECT_EQ(response.status(), grpc::health::v1::HealthCheckResponse::SERVING);
  }

  static void expect_refused(const std::shared_ptr<grpc::Channel>& channel) {
    grpc::health::v1::HealthCheckResponse response;
    const grpc::Status status = health_check(channel, &response);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE) << status.error_message();
  }

  static TempDir* dir_;
  static std::optional<TlsFiles> files_;
  static std::string why_not_;
};

TempDir* TlsRoundTrip::dir_ = nullptr;
std::optional<TlsFiles> TlsRoundTrip::files_;
std::string TlsRoundTrip::why_not_;

TEST_F(TlsRoundTrip, ClientTrustingTheCaIsServed) {
  const auto server = start(tls_options());
  ASSERT_NE(server.server, nullptr);
  EXPECT_TRUE(tls_enabled(tls_options()));
  expect_serving(channel(server.port, tls_client(files_->ca_cert)));
  // Without a name override the certificate's IP:127.0.0.1 subjectAltName is what matches.
  expect_serving(channel(server.port, tls_client(files_->ca_cert), ""));
}

TEST_F(TlsRoundTrip, PlaintextClientIsRefused) {
  const auto server = start(tls_options());
  ASSERT_NE(server.server, nullptr);
  expect_refused(channel(server.port, grpc::InsecureChannelCredentials()));
}

TEST_F(TlsRoundTrip, ClientTrustingAnotherCaIsRefused) {
  const auto server = start(tls_options());
  ASSERT_NE(server.server, nullptr);
  expect_refused(channel(server.port, tls_client(files_->other_ca_cert)));
}

TEST_F(TlsRoundTrip, ClientNameMismatchIsRefused) {
  const auto server = start(tls_options());
  ASSERT_NE(server.server, nullptr);
  expect_refused(channel(server.port, tls_client(files_->ca_cert), "not-localhost.example"));
}

TEST_F(TlsRoundTrip, ClientCaRequiresAVerifiedClientCertificate) {
  ServerOptions options = tls_options();
  options.tls_client_ca = files_->ca_cert;
  const auto server = start(options);
  ASSERT_NE(server.server, nullptr);
  expect_refused(channel(server.port, tls_client(files_->ca_cert)));
  // A certificate that does not chain to --tls-client-ca: proves VERIFY, not just REQUIRE.
  expect_refused(channel(server.port, tls_client(files_->ca_cert, files_->other_ca_cert, files_->other_ca_key)));
  expect_serving(channel(server.port, tls_client(files_->ca_cert, files_->client_cert, files_->client_key)));
}

// make_server_credentials cannot see that a key does not belong to its certificate (that needs a
// TLS library); gRPC finds out when it adds the port, and the server does not start.
TEST_F(TlsRoundTrip, KeyOfAnotherCertificateFailsWhenTheServerStarts) {
  ServerOptions options = tls_options();
  options.tls_key = files_->client_key;
  auto credentials = make_server_credentials(options);
  ASSERT_TRUE(credentials.ok());
  grpc::ServerBuilder builder;
  int port = 0;
  builder.AddListeningPort("127.0.0.1:0", *credentials, &port);
  TokenCheckingService service(Authenticator{});
  builder.RegisterCallbackGenericService(&service);
  const auto server = builder.BuildAndStart();
  EXPECT_TRUE(server == nullptr || port == 0) << "port " << port;
  if (server) server->Shutdown(std::chrono::system_clock::now());
}

grpc::Status generic_call(const std::shared_ptr<grpc::Channel>& channel, const std::string& method,
                          const std::string& token) {
  grpc::GenericStub stub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  // What clients are told to do: the standard access-token call credentials (TLS channels only).
  if (!token.empty()) context.set_credentials(grpc::AccessTokenCredentials(token));
  const grpc::ByteBuffer request(nullptr, 0);
  grpc::ByteBuffer response;
  std::promise<grpc::Status> done;
  stub.UnaryCall(&context, method, grpc::StubOptions(), &request, &response,
                 [&done](grpc::Status status) { done.set_value(std::move(status)); });
  return done.get_future().get();
}

TEST_F(TlsRoundTrip, BearerTokensFromAccessTokenCredentialsAreChecked) {
  TempDir tokens;
  const auto authenticator = make_authenticator(tokens, "user-token-1\n", "admin-token-1\n");
  TokenCheckingService service(authenticator);
  const auto server = start(tls_options(), &service);
  ASSERT_NE(server.server, nullptr);
  const auto client = channel(server.port, tls_client(files_->ca_cert));
  const std::string user_rpc = "/animspace.test.Tokens/Read";
  const std::string admin_rpc = "/animspace.test.Tokens/ResetAdmin";

  grpc::Status status = generic_call(client, user_rpc, "");
  EXPECT_EQ(status.error_code(), UN) << status.error_message();
  EXPECT_EQ(status.error_message(), "missing bearer token in 'authorization' metadata");
  EXPECT_EQ(generic_call(client, user_rpc, "nope").error_code(), UN);
  status = generic_call(client, user_rpc, "user-token-1");
  EXPECT_TRUE(status.ok()) << status.error_code() << ": " << status.error_message();
  status = generic_call(client, admin_rpc, "user-token-1");
  EXPECT_EQ(status.error_code(), PD);
  EXPECT_EQ(status.error_message(), admin_rpc + " is an admin RPC: it needs an admin token");
  status = generic_call(client, admin_rpc, "admin-token-1");
  EXPECT_TRUE(status.ok()) << status.error_code() << ": " << status.error_message();
  // Health stays public: the token check is per handler, not per server.
  expect_serving(client);
}

}  // namespace
}  // namespace animspace::server
