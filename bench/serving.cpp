#include "bench/serving.h"

#include <thread>

#include "clients/cpp/client.h"

namespace animspace::bench {

bool wait_until_serving(const std::string& address, std::chrono::seconds timeout) {
  Client client(address);
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    try {
      if (client.health() == grpc::health::v1::HealthCheckResponse::SERVING) return true;
    } catch (const std::exception&) {
      // not listening yet
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

}  // namespace animspace::bench
