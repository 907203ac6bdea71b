# PostgreSQL for the compose stack when no registry can be reached (CI):
# the distribution's server on the local Debian base (.ci/images/build),
# initialised at first start as the official image is: POSTGRES_USER,
# POSTGRES_PASSWORD (or POSTGRES_PASSWORD_FILE) and POSTGRES_DB from the environment, data in
# /var/lib/postgresql/data, `pg_isready` for the health check.
# A lab with a registry runs the official postgres image instead.
ARG BASE_IMAGE=zwidth-ci/bookworm
FROM ${BASE_IMAGE}
RUN apt-get update \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends postgresql-15 \
 && rm -rf /var/lib/apt/lists/* \
 && rm -rf /etc/postgresql/15/main /var/lib/postgresql/15
COPY postgres-entrypoint.sh /usr/local/bin/postgres-entrypoint
ENV PATH=/usr/lib/postgresql/15/bin:$PATH PGDATA=/var/lib/postgresql/data
VOLUME /var/lib/postgresql/data
# SIGINT is PostgreSQL's fast shutdown (SIGTERM waits for every client).
STOPSIGNAL SIGINT
EXPOSE 5432
ENTRYPOINT ["postgres-entrypoint"]
CMD ["postgres"]
