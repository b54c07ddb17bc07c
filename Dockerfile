# syntax=docker/dockerfile:1
# distband-server container: a build stage with the full toolchain, a runtime stage with only the shared
# libraries the binaries load, running as a non-root user.
#
#   docker build -t distband:latest .
#   docker run --rm -p 50051:50051 distband:latest --threads 4 --max-queries 4
#   docker run --rm --network host --entrypoint distband distband:latest info --server 127.0.0.1:50051
#
# Health: the image has no probe binary, so there is no Docker HEALTHCHECK. The server serves the standard
# grpc.health.v1 service; Kubernetes probes it natively (deploy/k8s/deployment.yaml, `grpc: port: 50051`), and
# `distband health --server HOST:PORT` checks it by hand.

ARG DEBIAN_IMAGE=debian:bookworm-slim

# ---- build -------------------------------------------------------------------------------------------------
FROM ${DEBIAN_IMAGE} AS build
SHELL ["/bin/bash", "-o", "pipefail", "-c"]
WORKDIR /src
# Dependencies first, so the (slow) package layer is reused while only the sources change.
COPY scripts/install-deps scripts/install-deps
RUN scripts/install-deps && rm -rf /var/lib/apt/lists/*
COPY . .
RUN cmake -S . -B /build -G Ninja -DCMAKE_BUILD_TYPE=Release -DDISTBAND_BUILD_TESTS=OFF \
 && cmake --build /build --target distband-server distband -j"$(nproc)" \
 && mkdir -p /out \
 && cp /build/server/distband-server /build/client/distband /out/ \
 && strip --strip-unneeded /out/distband-server /out/distband

# ---- runtime -----------------------------------------------------------------------------------------------
FROM ${DEBIAN_IMAGE} AS runtime
SHELL ["/bin/bash", "-o", "pipefail", "-c"]
COPY scripts/install-runtime-deps /usr/local/lib/distband/install-runtime-deps
RUN /usr/local/lib/distband/install-runtime-deps && rm -rf /var/lib/apt/lists/*
COPY --from=build /out/distband-server /out/distband /usr/local/bin/
# Fail the image build if the runtime package list misses a library the binaries load.
RUN if ldd /usr/local/bin/distband-server /usr/local/bin/distband | grep "not found"; then exit 1; fi
# A fixed numeric uid/gid so Kubernetes' runAsNonRoot can verify it without reading /etc/passwd.
RUN groupadd --system --gid 10001 distband \
 && useradd --system --uid 10001 --gid 10001 --no-create-home --home-dir /nonexistent \
            --shell /usr/sbin/nologin distband
USER 10001:10001
EXPOSE 50051
# distband-server exits 0 on SIGTERM after draining running streams for --grace-seconds.
STOPSIGNAL SIGTERM
ENTRYPOINT ["distband-server"]
CMD ["--listen", "0.0.0.0:50051"]
