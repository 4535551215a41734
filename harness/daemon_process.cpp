#include "harness/daemon_process.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "harness/build_tree.h"

namespace animspace::harness {

std::filesystem::path daemon_binary() {
  if (const char* env = std::getenv("ANIMSPACED")) return env;
  return program_path("animspaced");
}

std::filesystem::path transport_floor_binary() {
  if (const char* env = std::getenv("ANIMSPACE_TRANSPORT_FLOOR")) return env;
  return program_path("animspace-transport-floor");
}

DaemonProcess::DaemonProcess(const std::vector<std::string>& extra_args, const std::filesystem::path& work_dir,
                             std::chrono::milliseconds timeout)
    : DaemonProcess(daemon_binary(), extra_args, work_dir, timeout) {}

DaemonProcess::DaemonProcess(const std::filesystem::path& binary, const std::vector<std::string>& extra_args,
                             const std::filesystem::path& work_dir, std::chrono::milliseconds timeout)
    : log_path_(work_dir / (binary.filename().string() + ".log")) {
  const std::string name = binary.filename().string();
  const auto port_file = work_dir / (name + ".port");
  std::filesystem::remove(port_file);
  std::vector<std::string> args{binary.string(), "--port-file", port_file.string()};
  if (std::find(extra_args.begin(), extra_args.end(), "--listen") == extra_args.end()) {
    args.insert(args.end(), {"--listen", "127.0.0.1:0"});
  }
  // A test decides when its daemon sees new versions: no repository poll unless it asks for one
  // (animspaced polls every 30 s by default; other binaries, the transport floor, have no poll).
  if (name.rfind("animspaced", 0) == 0 &&
      std::find(extra_args.begin(), extra_args.end(), "--poll-interval-s") == extra_args.end()) {
    args.insert(args.end(), {"--poll-interval-s", "0"});
  }
  args.insert(args.end(), extra_args.begin(), extra_args.end());

  pid_ = ::fork();
  if (pid_ < 0) throw std::runtime_error("fork failed");
  if (pid_ == 0) {
    const int fd = ::open(log_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      ::dup2(fd, STDOUT_FILENO);
      ::dup2(fd, STDERR_FILENO);
    }
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }

  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    std::ifstream in(port_file);
    if (in >> port_ && port_ > 0) return;
    int status = 0;
    if (::waitpid(pid_, &status, WNOHANG) == pid_) {
      pid_ = -1;
      throw std::runtime_error(name + " exited before listening; log:\n" + log());
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  throw std::runtime_error(name + " did not write its port in time; log:\n" + log());
}

DaemonProcess::~DaemonProcess() {
  if (pid_ > 0) {
    ::kill(pid_, SIGKILL);
    int status = 0;
    ::waitpid(pid_, &status, 0);
  }
}

std::string DaemonProcess::log() const {
  std::ifstream in(log_path_);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

void DaemonProcess::send_signal(int signal_number) const {
  if (pid_ > 0) ::kill(pid_, signal_number);
}

int DaemonProcess::wait_for_exit(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    int status = 0;
    const pid_t done = ::waitpid(pid_, &status, WNOHANG);
    if (done == pid_) {
      pid_ = -1;
      if (WIFEXITED(status)) return WEXITSTATUS(status);
      if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return -1;
}

}  // namespace animspace::harness
