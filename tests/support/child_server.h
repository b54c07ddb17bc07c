// ChildServer: the distband-server binary started as a child process on 127.0.0.1 port 0, for tests and benches
// that need the server's own process (its RSS and threads from /proc, its exit status, signals).
// Contract: the constructor forks and execs `binary --listen 127.0.0.1:0 ARGS...`, collects the child's stdout and
// stderr on a thread, and waits up to 10 s for the "(port N," of its listening line (port() stays 0 if it never
// comes). The destructor SIGKILLs a child that is still running. Header-only; POSIX; not synchronised except log().
#pragma once

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <fstream>
#include <mutex>
#include <regex>
#include <string>
#include <thread>
#include <vector>

namespace distband {

class ChildServer {
 public:
  using Clock = std::chrono::steady_clock;

  ChildServer(const std::string& binary, const std::vector<std::string>& args) {
    int out[2];
    if (pipe(out) != 0) return;
    pid_ = fork();
    if (pid_ == 0) {
      dup2(out[1], 1);
      dup2(out[1], 2);
      close(out[0]);
      std::vector<std::string> all = {binary, "--listen", "127.0.0.1:0"};
      all.insert(all.end(), args.begin(), args.end());
      std::vector<char*> argv;
      for (auto& a : all) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
    close(out[1]);
    log_fd_ = out[0];
    reader_ = std::thread([this] {
      char buf[4096];
      for (ssize_t n; (n = read(log_fd_, buf, sizeof buf)) > 0;) {
        std::lock_guard lock(mu_);
        log_.append(buf, size_t(n));
      }
    });
    const auto deadline = Clock::now() + std::chrono::seconds(10);
    const std::regex port_re(R"(\(port (\d+),)");
    while (Clock::now() < deadline && port_ == 0) {
      std::smatch m;
      const std::string text = log();
      if (std::regex_search(text, m, port_re)) port_ = std::stoi(m[1]);
      else std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }
  ChildServer(const ChildServer&) = delete;
  ChildServer& operator=(const ChildServer&) = delete;
  ~ChildServer() {
    if (pid_ > 0 && !exited_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    if (reader_.joinable()) reader_.join();
    if (log_fd_ >= 0) close(log_fd_);
  }

  int port() const { return port_; }
  pid_t pid() const { return pid_; }
  std::string target() const { return "127.0.0.1:" + std::to_string(port_); }
  std::string log() {
    std::lock_guard lock(mu_);
    return log_;
  }
  /// A field of /proc/PID/status as a number ("Threads:", "VmRSS:" and "VmHWM:" in KiB); -1 when unreadable.
  int64_t status(const char* field) const {
    std::ifstream in("/proc/" + std::to_string(pid_) + "/status");
    const std::string key(field);
    for (std::string line; std::getline(in, line);)
      if (line.rfind(key, 0) == 0) return std::stoll(line.substr(key.size()));
    return -1;
  }
  int threads() const { return int(status("Threads:")); }
  /// Sends `signal` to the child.
  void signal(int sig) const { kill(pid_, sig); }
  /// Waits for the child to exit: its exit status, -2 when a signal killed it, -1 on timeout.
  int waitExit(std::chrono::milliseconds timeout) {
    const auto deadline = Clock::now() + timeout;
    while (Clock::now() < deadline) {
      int st = 0;
      if (waitpid(pid_, &st, WNOHANG) == pid_) {
        exited_ = true;
        return WIFEXITED(st) ? WEXITSTATUS(st) : -2;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return -1;
  }

 private:
  pid_t pid_ = -1;
  int port_ = 0;
  int log_fd_ = -1;
  bool exited_ = false;
  std::thread reader_;
  std::mutex mu_;
  std::string log_;
};

}  // namespace distband
