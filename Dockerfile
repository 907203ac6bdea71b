# zwidth service image. Build: docker build -t zwidth .
FROM rust:1-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked --bin zwidth

FROM debian:bookworm-slim
COPY --from=build /src/target/release/zwidth /usr/local/bin/zwidth
VOLUME /data
# Beyond loopback the service needs a token: pass ZWIDTH_TOKENS at run time.
ENV ZWIDTH_DB=/data/zwidth.db ZWIDTH_BIND=0.0.0.0:8080
EXPOSE 8080
CMD ["zwidth", "serve"]
