# zwidth image: `zwidth serve` (the API; SQLite or PostgreSQL) and
# `zwidth worker` (PostgreSQL). Build: docker build -t zwidth .
# The context leaves out target/ and local databases (.dockerignore).
FROM rust:1-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked --bin zwidth

FROM debian:bookworm-slim
# curl for the health check; a user of its own (never root).
RUN apt-get update \
 && apt-get install -y --no-install-recommends curl ca-certificates \
 && rm -rf /var/lib/apt/lists/* \
 && useradd --system --uid 10001 --home-dir /data --create-home zwidth
COPY --from=build /src/target/release/zwidth /usr/local/bin/zwidth
USER zwidth
VOLUME /data
# Beyond loopback the service needs a token: pass ZWIDTH_TOKENS at run time.
ENV ZWIDTH_DB=/data/zwidth.db ZWIDTH_BIND=0.0.0.0:8080
EXPOSE 8080
# The API answers /healthz (a worker has no port: its compose service
# overrides this with `disable: true`).
HEALTHCHECK --interval=10s --timeout=3s --start-period=10s --retries=3 \
  CMD curl -fsS http://127.0.0.1:8080/healthz || exit 1
CMD ["zwidth", "serve"]
