#!/bin/sh
# First start: make the cluster in $PGDATA as the official image does (user,
# password and database from the environment; trust on the container's own
# socket, a scram password over the network); every start: run the server as
# the postgres user. An initialised $PGDATA is kept.
set -eu
# POSTGRES_PASSWORD_FILE (a compose secret), as the official image reads it.
if [ -n "${POSTGRES_PASSWORD_FILE:-}" ]; then
  [ -z "${POSTGRES_PASSWORD:-}" ] || { echo "postgres-entrypoint: give POSTGRES_PASSWORD or POSTGRES_PASSWORD_FILE, not both" >&2; exit 2; }
  POSTGRES_PASSWORD=$(head -n 1 "$POSTGRES_PASSWORD_FILE")
fi
: "${POSTGRES_PASSWORD:?set POSTGRES_PASSWORD or POSTGRES_PASSWORD_FILE}"
user="${POSTGRES_USER:-postgres}"
db="${POSTGRES_DB:-$user}"
if [ "$(id -u)" = 0 ]; then
  # The socket's directory: a tmpfs under a read-only root (docker-compose.yml).
  mkdir -p /run/postgresql
  chown postgres:postgres /run/postgresql
  chmod 2775 /run/postgresql
  mkdir -p "$PGDATA"
  chown postgres:postgres "$PGDATA"
  chmod 700 "$PGDATA"
  exec setpriv --reuid=postgres --regid=postgres --init-groups "$0" "$@"
fi
if [ ! -s "$PGDATA/PG_VERSION" ]; then
  echo "postgres-entrypoint: initialising $PGDATA (user $user, database $db)"
  pw=$(mktemp)
  printf '%s\n' "$POSTGRES_PASSWORD" > "$pw"
  initdb --username="$user" --pwfile="$pw" --auth-local=trust --auth-host=scram-sha-256 --encoding=UTF8 -D "$PGDATA" >/dev/null
  rm -f "$pw"
  echo "host all all all scram-sha-256" >> "$PGDATA/pg_hba.conf"
  echo "listen_addresses = '*'" >> "$PGDATA/postgresql.conf"
  if [ "$db" != postgres ]; then
    echo "CREATE DATABASE \"$db\" OWNER \"$user\";" | postgres --single -D "$PGDATA" postgres >/dev/null
  fi
  echo "postgres-entrypoint: initialised"
fi
exec "$@"
