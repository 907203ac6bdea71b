"""Check docker-compose.yml's text: valid against the Compose Specification's
JSON schema (as shipped in the docker-compose 1.29.2 wheel, fetched from
PyPI), and the wiring issue 14 asks for: PostgreSQL with a health check, the
API and the workers waiting for it to be healthy, a worker replica count,
the API's health check; the agent dialling the API by its service name.
(.ci/compose brings the same file up on a Docker engine.)

usage: python3 .ci/compose_check.py SCHEMA.json docker-compose.yml
"""
import json
import os
import sys
import tempfile

import jsonschema
import yaml

schema_path, compose_path = sys.argv[1], sys.argv[2]
schema = json.load(open(schema_path))
doc = yaml.safe_load(open(compose_path))
# YAML anchors and merge keys are resolved by the loader; extension fields
# (x-…) are allowed by the specification.
jsonschema.validate(doc, schema, cls=jsonschema.Draft201909Validator)

services = doc["services"]
checks = []


def check(what, ok):
    checks.append(what)
    if not ok:
        print(f"compose: FAILED: {what}")
        sys.exit(1)


check("a postgres service with a health check", "healthcheck" in services["postgres"])
for name in ("api", "worker"):
    dep = services[name].get("depends_on", {})
    check(f"{name} waits for a healthy postgres", dep.get("postgres", {}).get("condition") == "service_healthy")
    check(f"{name} reads the database from ZWIDTH_DB", "ZWIDTH_DB" in services[name]["environment"])
check("worker has a replica count", services["worker"].get("deploy", {}).get("replicas", 0) >= 1)
check("worker runs `zwidth worker`", services["worker"]["command"][:2] == ["zwidth", "worker"])
check("api runs `zwidth serve --api-only`", services["api"]["command"] == ["zwidth", "serve", "--api-only"])
check("api has a health check", "test" in services["api"].get("healthcheck", {}))
# Secrets are files (compose secrets), never environment variables (issue 45
# item 6): no value of a variable named like a secret, no interpolated
# secret, the password not in the database URL.
secretish = ("TOKEN", "PASSWORD", "KEY", "SECRET")
for name, svc in services.items():
    for var, value in (svc.get("environment") or {}).items():
        if any(w in var for w in secretish):
            check(f"{name}: {var} names a file under /run/secrets, not a secret",
                  var.endswith("_FILE") or var.endswith("_CERT") or var.endswith("_KEY"))
            check(f"{name}: {var} is a file under /run/secrets", str(value).startswith("/run/secrets/"))
    db = str((svc.get("environment") or {}).get("ZWIDTH_DB", ""))
    userinfo = db.split("//", 1)[-1].split("@", 1)[0] if "@" in db else ""
    check(f"{name}: no password in ZWIDTH_DB", ":" not in userinfo and "password=" not in db)
for name, files in [("api", ["zwidth_token", "pg_password"]), ("worker", ["pg_password"]),
                    ("postgres", ["pg_password"]), ("agent", ["rig_token"]), ("zwidth", ["zwidth_token"])]:
    check(f"{name} is given its secrets ({', '.join(files)})",
          all(f in services[name].get("secrets", []) for f in files))
check("every secret is a file", all("file" in v for v in doc.get("secrets", {}).values()))
check("api reads its token from its secret", services["api"]["environment"].get("ZWIDTH_TOKEN_FILE") == "/run/secrets/zwidth_token")
check("postgres reads its password from its secret",
      services["postgres"]["environment"].get("POSTGRES_PASSWORD_FILE") == "/run/secrets/pg_password")
check("the API is published on loopback only (reads need no token)",
      all(p == "127.0.0.1:8080:8080" for name in ("api", "zwidth") for p in services[name]["ports"]))
check("agent dials the API by its service name", services["agent"]["environment"]["ZWIDTH_SERVER"] == "http://api:8080")
check("the API answers to that name (its Host check)", "api" in services["api"]["environment"].get("ZWIDTH_HOSTS", "").split(","))
check("agent runs `zwidth agent`", services["agent"]["command"][:2] == ["zwidth", "agent"])
# Secrets never enter the build context (COPY . . in the build stage).
ignored = [l.strip() for l in open(os.path.join(os.path.dirname(compose_path) or ".", ".dockerignore"))]
for secret in (".env", "*.pem", "*.key", "secrets/"):
    check(f".dockerignore leaves out {secret}", secret in ignored)
check("postgres restarts", services["postgres"].get("restart") == "unless-stopped")
for name, svc in services.items():
    check(f"{name}: no privilege gained (no-new-privileges)", "no-new-privileges:true" in svc.get("security_opt", []))
    check(f"{name}: every capability dropped", svc.get("cap_drop") == ["ALL"])
    check(f"{name}: a memory ceiling", bool(svc.get("mem_limit")))
    check(f"{name}: a read-only root with a tmpfs /tmp", svc.get("read_only") is True and "/tmp" in svc.get("tmpfs", []))
    if name != "postgres":
        check(f"{name}: no capability added back", not svc.get("cap_add"))

# The image script's Debian mirror is this machine's apt's (issue 45 item 13).
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "images"))
import apt_mirror  # noqa: E402

with tempfile.TemporaryDirectory() as apt:
    check("no apt sources: Debian's own mirror", apt_mirror.mirror("bookworm", apt) == apt_mirror.DEFAULT)
    os.makedirs(os.path.join(apt, "sources.list.d"))
    with open(os.path.join(apt, "sources.list"), "w") as f:
        f.write("# deb http://commented.example/debian bookworm main\n"
                "deb [arch=amd64 signed-by=/k.gpg] http://lab-mirror.example/debian-security bookworm-security main\n"
                "deb-src http://src.example/debian bookworm main\n")
    with open(os.path.join(apt, "sources.list.d", "debian.sources"), "w") as f:
        f.write("Types: deb\nURIs: http://off.example/debian\nSuites: bookworm\nEnabled: no\n\n"
                "Types: deb deb-src\nURIs: http://lab-mirror.example/debian/\n"
                "Suites: bookworm bookworm-updates\nComponents: main\n")
    check("the mirror of the machine's deb822 sources, not the security, source-only or disabled ones",
          apt_mirror.mirror("bookworm", apt) == "http://lab-mirror.example/debian")
    with open(os.path.join(apt, "sources.list.d", "proxy.list"), "w") as f:
        f.write("deb http://apt-proxy.lab:3142/debian bookworm main contrib\n")
    check("a one-line .list source comes first", apt_mirror.mirror("bookworm", apt) == "http://apt-proxy.lab:3142/debian")
    check("another suite: Debian's own", apt_mirror.mirror("trixie", apt) == apt_mirror.DEFAULT)

# The TLS path (issue 45 item 3): docker-compose.tls.yml over this file.
tls = yaml.safe_load(open(os.path.join(os.path.dirname(compose_path) or ".", "docker-compose.tls.yml")))
jsonschema.validate(tls, schema, cls=jsonschema.Draft201909Validator)
tapi, tagent = tls["services"]["api"], tls["services"]["agent"]
check("tls: the API serves its certificate and key from secrets",
      tapi["environment"] == {"ZWIDTH_TLS_CERT": "/run/secrets/tls_cert", "ZWIDTH_TLS_KEY": "/run/secrets/tls_key"})
check("tls: the API keeps its other secrets", all(f in tapi["secrets"] for f in ("zwidth_token", "pg_password", "tls_cert", "tls_key")))
check("tls: the API's health check speaks HTTPS, trusting the CA",
      "https://localhost:8080/healthz" in tapi["healthcheck"]["test"] and "/run/secrets/tls_ca" in tapi["healthcheck"]["test"])
check("tls: the agent dials wss by the service name, trusting the CA",
      tagent["environment"] == {"ZWIDTH_SERVER": "https://api:8080", "ZWIDTH_CA_FILE": "/run/secrets/tls_ca"}
      and all(f in tagent["secrets"] for f in ("rig_token", "tls_ca")))
check("tls: its secrets are files", all("file" in v for v in tls["secrets"].values()))

for name, svc in services.items():
    for dep in svc.get("depends_on", {}):
        check(f"{name} depends on a service that exists ({dep})", dep in services)
print(f"compose: {len(checks)} passed (schema valid)")
