// httpGet: a minimal HTTP/1.0 GET to a loopback port, for tests that read a metrics endpoint or Prometheus' HTTP API
// without an HTTP library. Contract: connects to 127.0.0.1:PORT, sends `GET path` and reads until the server closes
// (HTTP/1.0: no chunking, no keep-alive); status -1 when nothing HTTP came back within the timeout (refused, reset,
// not HTTP). urlEncode() escapes a query-string value. Header-only; POSIX.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <string>

namespace distband {

struct HttpResponse {
  int status = -1;
  std::string body;
};

inline HttpResponse httpGet(int port, const std::string& path,
                            std::chrono::milliseconds timeout = std::chrono::milliseconds(5000)) {
  HttpResponse r;
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return r;
  timeval tv{};
  tv.tv_sec = long(timeout.count() / 1000);
  tv.tv_usec = long(timeout.count() % 1000) * 1000;
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(uint16_t(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    ::close(fd);
    return r;
  }
  const std::string request = "GET " + path + " HTTP/1.0\r\nHost: 127.0.0.1\r\nAccept: */*\r\n\r\n";
  if (::send(fd, request.data(), request.size(), MSG_NOSIGNAL) != ssize_t(request.size())) {
    ::close(fd);
    return r;
  }
  std::string raw;
  char buf[16384];
  for (ssize_t n; (n = ::recv(fd, buf, sizeof buf, 0)) > 0;) raw.append(buf, size_t(n));
  ::close(fd);
  int status = 0;
  if (raw.rfind("HTTP/1.", 0) != 0 || std::sscanf(raw.c_str(), "HTTP/1.%*d %d", &status) != 1) return r;
  const size_t body = raw.find("\r\n\r\n");
  r.status = status;
  r.body = body == std::string::npos ? std::string() : raw.substr(body + 4);
  return r;
}

inline std::string urlEncode(const std::string& s) {
  static const char hex[] = "0123456789ABCDEF";
  std::string out;
  for (const unsigned char c : s) {
    if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' || c == '_' ||
        c == '.' || c == '~') {
      out += char(c);
    } else {
      out += '%';
      out += hex[c >> 4];
      out += hex[c & 15];
    }
  }
  return out;
}

}  // namespace distband
