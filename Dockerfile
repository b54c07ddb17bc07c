# syntax=docker/dockerfile:1
# distband-server container: a build stage with the toolchain, a runtime stage with only the shared libraries
# the server and its health probe load, running as the non-root uid/gid 10001.
#
#   scripts/container build        podman, no registry needed: makes debian:bookworm-slim with debootstrap
#   docker build -t distband:latest .                     the same Dockerfile where a registry is reachable
#   docker run --rm -p 50051:50051 distband:latest --listen 0.0.0.0:50051 --threads 4 --max-queries 4
#
# Arguments after the image name replace CMD, so pass `--listen 0.0.0.0:50051` again with any other flag: the
# server's own default listens on loopback only, and --listen may be given only once.
#
# The image ships distband-server (the entrypoint) and distband-health (the HEALTHCHECK: grpc.health.v1 Check,
# exit 0 iff SERVING), not the distband CLI, which writes .vdb level sets and PNG slices (libblosc, libpng: libraries
# the server does not use). Query a container with the CLI from outside it.

ARG DEBIAN_IMAGE=debian:bookworm-slim

# ---- build -------------------------------------------------------------------------------------------------
FROM ${DEBIAN_IMAGE} AS build
SHELL ["/bin/bash", "-o", "pipefail", "-c"]
WORKDIR /src
# Dependencies first, so the (slow) package layer is reused while only the sources change; only the build group
# (no test, benchmark or Python packages).
COPY scripts/install-deps scripts/install-deps
RUN scripts/install-deps build && rm -rf /var/lib/apt/lists/*
# Only what CMake reads (bench/ and tests/ are configured even with tests off), so edits to docs, deploy files
# or scripts do not recompile.
COPY CMakeLists.txt ./
COPY proto proto
COPY core core
COPY server server
COPY client client
COPY bench bench
COPY tests tests
COPY scripts/ccache-compile scripts/ccache-compile
# --as-needed (Debian's gcc default, explicit for other toolchains): the server and the probe record only the
# libraries they call, not libblosc/libpng that the core library's link interface lists.
# ccache (in the build group) compiles only where /ccache is mounted: `scripts/container build` lends the host's
# cache there, which scripts/build filled with the same files compiled the same way (scripts/ccache-compile: paths
# hashed relative to the source tree, hence the build tree inside /src); a plain `docker build` compiles everything.
RUN if [ -d /ccache ]; then export CCACHE_DIR=/ccache && ccache --zero-stats >/dev/null; else export CCACHE_DISABLE=1; fi \
 && cmake -S . -B /src/build -G Ninja -DCMAKE_BUILD_TYPE=Release -DDISTBAND_BUILD_TESTS=OFF \
          -DCMAKE_CXX_COMPILER_LAUNCHER=/src/scripts/ccache-compile \
          -DCMAKE_EXE_LINKER_FLAGS="-Wl,--as-needed" >/dev/null \
 && cmake --build /src/build --target distband-server distband-health -j"$(nproc)" \
 && if [ -d /ccache ]; then echo "ccache (the host's): $(ccache --print-stats | grep -E '^(direct|preprocessed)_cache_hit|^cache_miss' | tr '\n' ' ')"; fi \
 && mkdir -p /out \
 && cp /src/build/server/distband-server /src/build/client/distband-health /out/ \
 && strip --strip-unneeded /out/distband-server /out/distband-health

# ---- runtime -----------------------------------------------------------------------------------------------
FROM ${DEBIAN_IMAGE} AS runtime
SHELL ["/bin/bash", "-o", "pipefail", "-c"]
COPY scripts/install-runtime-deps /usr/local/lib/distband/install-runtime-deps
# Library packages only, then no apt lists, caches or logs in the layer.
RUN /usr/local/lib/distband/install-runtime-deps server \
 && apt-get clean \
 && rm -rf /var/lib/apt/lists/* /var/cache/apt/*.bin /var/cache/debconf/*-old /var/lib/dpkg/*-old \
           /var/log/apt /var/log/dpkg.log
COPY --from=build /out/distband-server /out/distband-health /usr/local/bin/
# Fail the image build if the runtime package list misses a library the binaries load (Embree is loaded by name
# when a parity sign first needs it: not in ldd's list, so looked up in the loader's cache).
RUN if ldd /usr/local/bin/distband-server /usr/local/bin/distband-health | grep "not found"; then exit 1; fi \
 && ldconfig -p | grep -q "libembree3.so.3 " \
 && distband-server --version && distband-health --help >/dev/null
# A fixed numeric uid/gid so Kubernetes' runAsNonRoot can verify it without reading /etc/passwd.
RUN groupadd --system --gid 10001 distband \
 && useradd --system --uid 10001 --gid 10001 --no-create-home --home-dir /nonexistent \
            --shell /usr/sbin/nologin distband
USER 10001:10001
# 50051: gRPC. 9464: Prometheus metrics, served only when --metrics-listen 0.0.0.0:9464 is passed (no token: publish
# it to your Prometheus only, docs/operations.md).
EXPOSE 50051 9464
# The gRPC health service on the default port (change it here too if you change --listen's port). Kubernetes
# ignores HEALTHCHECK and probes grpc.health.v1 natively (deploy/k8s); podman keeps it only in docker-format
# images (scripts/container builds with --format docker).
HEALTHCHECK --interval=15s --timeout=5s --start-period=10s --retries=3 \
  CMD ["distband-health", "--server", "127.0.0.1:50051", "--timeout", "4"]
# distband-server exits 0 on SIGTERM after draining running streams for --grace-seconds (it handles the signal
# itself, also as PID 1).
STOPSIGNAL SIGTERM
ENTRYPOINT ["distband-server"]
CMD ["--listen", "0.0.0.0:50051"]
