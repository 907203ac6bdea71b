# zwidth image: `zwidth serve` (the API; SQLite or PostgreSQL), `zwidth
# worker` (PostgreSQL) and `zwidth agent` (a rig). Build: docker build -t zwidth .
# The context leaves out target/ and local databases (.dockerignore).
#
# Without a registry (CI: no image can be pulled there, so neither the rust
# image nor debian:bookworm-slim), .ci/images/build makes a Debian base with
# debootstrap and builds this file on it, taking the binary the host built
# (PREBUILT, a path in the context) instead of compiling inside:
#   docker build --build-arg BUILDER_IMAGE=zwidth-ci/bookworm \
#     --build-arg RUNTIME_IMAGE=zwidth-ci/bookworm \
#     --build-arg PREBUILT=.ci/images/prebuilt/zwidth -t zwidth .
ARG BUILDER_IMAGE=rust:1-bookworm
ARG RUNTIME_IMAGE=debian:bookworm-slim

FROM ${BUILDER_IMAGE} AS build
ARG PREBUILT=
WORKDIR /src
COPY . .
RUN if [ -n "$PREBUILT" ]; then install -D -m 0755 "$PREBUILT" target/release/zwidth; \
    else cargo build --release --locked --bin zwidth; fi

FROM ${RUNTIME_IMAGE}
# curl for the health check; a user of its own (never root).
RUN apt-get update \
 && apt-get install -y --no-install-recommends curl ca-certificates \
 && rm -rf /var/lib/apt/lists/* \
 && useradd --system --uid 10001 --home-dir /data --create-home zwidth
COPY --from=build /src/target/release/zwidth /usr/local/bin/zwidth
USER zwidth
WORKDIR /data
VOLUME /data
# Beyond loopback the service needs a token: pass ZWIDTH_TOKENS at run time.
ENV ZWIDTH_DB=/data/zwidth.db ZWIDTH_BIND=0.0.0.0:8080
EXPOSE 8080
# The API answers /healthz (a worker has no port: its compose service
# overrides this with `disable: true`).
HEALTHCHECK --interval=10s --timeout=3s --start-period=10s --retries=3 \
  CMD curl -fsS http://127.0.0.1:8080/healthz || exit 1
CMD ["zwidth", "serve"]
