# drawcal service image.
#
#   docker build -t drawcal .
#   docker run -p 8080:8080 -v drawcal-data:/data drawcal
#
# Build stage: the Rust toolchain (>= 1.94 for sqlx 0.9), a locked release
# build of the one binary. SQL migrations are embedded in the binary.
FROM rust:1.95-slim-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
COPY src src
COPY migrations migrations
COPY benches benches
# Datasets the library embeds (include_str!) as built-in examples.
COPY tests/data tests/data
RUN cargo build --release --locked --bin drawcal \
 && strip target/release/drawcal

# Runtime stage: Debian slim, the binary, a non-root user, the database on a
# volume. No curl in the image: the health check speaks HTTP with bash.
FROM debian:bookworm-slim
RUN useradd --system --uid 10001 --user-group --home-dir /data --shell /usr/sbin/nologin drawcal \
 && mkdir -p /data && chown drawcal:drawcal /data
COPY --from=build /src/target/release/drawcal /usr/local/bin/drawcal
USER drawcal
WORKDIR /data
VOLUME ["/data"]
# Clients that reach the container by a name other than localhost need it
# allowed: docker run -e DRAWCAL_ALLOWED_HOST=calib.plant.example,10.0.0.5 ...
ENV DATABASE_URL=sqlite:///data/drawcal.db \
    DRAWCAL_LISTEN=0.0.0.0:8080 \
    DRAWCAL_WORKERS=1 \
    DRAWCAL_MAX_UPLOAD_BYTES=16777216 \
    RUST_LOG=info
EXPOSE 8080
HEALTHCHECK --interval=30s --timeout=5s --start-period=10s --retries=3 \
    CMD ["bash", "-c", "exec 3<>/dev/tcp/127.0.0.1/8080 && printf 'GET /ready HTTP/1.0\\r\\nHost: localhost\\r\\n\\r\\n' >&3 && head -n1 <&3 | grep -q ' 200 '"]
STOPSIGNAL SIGTERM
ENTRYPOINT ["drawcal"]
CMD ["serve"]
