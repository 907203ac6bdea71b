"""zwidth.Client against a real `zwidth serve` (the CLI's build in target/,
or $ZWIDTH_BIN) on a free port with a throwaway database: submit, watch,
results equal to the in-process engine's, trials, compare, cancel, rigs,
and every refusal an ApiError naming the field."""

import json
import re
import subprocess
import time

import pytest

import zwidth
from test_engines import EX, cli, without_elapsed


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    db = tmp_path_factory.mktemp("svc") / "zwidth.db"
    p = subprocess.Popen([cli(), "serve", "--db", str(db), "--bind", "127.0.0.1:0"],
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    url = None
    deadline = time.monotonic() + 60
    while url is None and time.monotonic() < deadline:
        line = p.stdout.readline()
        m = re.search(r"serving on (http://\S+)", line)
        if m:
            url = m.group(1)
    assert url, "the service did not start"
    token = (db.parent / "zwidth.db.token").read_text().strip()
    yield url, token
    p.terminate()
    p.wait(timeout=30)


def test_a_map_submitted_watched_and_read_equals_the_engine_in_process(service):
    url, token = service
    c = zwidth.Client(url, token=token)
    scene = json.loads((EX / "seed_2011.json").read_text())
    spec = {"kind": "map", "scene": scene, "method": "time", "criterion": "stability",
            "accuracy": "draft", "b": [0.0, 300.0]}
    e = c.submit(spec)
    assert e["state"] in ("queued", "running") and e["estimate"]["trials"] > 0
    done = c.watch(e["id"], poll_s=0.1, progress=True, timeout_s=120)
    assert done["state"] == "succeeded", done
    got = c.results(e["id"])
    want = zwidth.map(scene, method="time", criterion="stability", accuracy="draft", b=[0, 300])
    assert without_elapsed(got) == without_elapsed(want.to_dict())
    trials = c.trials(e["id"])
    assert len(trials) == want.to_dict()["trials"]
    # Two runs side by side: the same scene, so the table compares them.
    e2 = c.submit(spec)
    c.watch(e2["id"], poll_s=0.1, progress=False, timeout_s=120)
    table = c.compare([e["id"], e2["id"]], format="text")
    assert "K-width" in table
    assert isinstance(c.compare([e["id"], e2["id"]]), dict)
    # Ended: no cancel (409), and the refusal says so.
    with pytest.raises(zwidth.ApiError) as err:
        c.cancel(e["id"])
    assert err.value.status == 409


def test_a_running_experiment_cancels(service):
    url, token = service
    c = zwidth.Client(url, token=token)
    scene = json.loads((EX / "mode_lag_2011.json").read_text())
    e = c.submit({"kind": "map", "scene": scene, "accuracy": "reference"})
    c.cancel(e["id"])
    done = c.watch(e["id"], poll_s=0.1, progress=False, timeout_s=60)
    assert done["state"] == "cancelled"
    with pytest.raises(ValueError, match="state is cancelled"):
        c.results(e["id"])


def test_refusals_raise_api_error_naming_the_field(service):
    url, token = service
    c = zwidth.Client(url, token=token)
    with pytest.raises(zwidth.ApiError) as err:
        c.submit({"kind": "map", "scene": {"device": {"mass": -1}}, "accuracy": "draft"})
    assert err.value.status == 422 and err.value.field == "scene.device.mass", err.value
    assert isinstance(err.value, ValueError)
    # Without the token: 401, nothing stored.
    with pytest.raises(zwidth.ApiError) as err:
        zwidth.Client(url).submit({"kind": "compare", "accuracy": "draft"})
    assert err.value.status == 401
    with pytest.raises(zwidth.ApiError) as err:
        c.status("no-such-id")
    assert err.value.status in (404, 422)
    assert isinstance(c.rigs(), list) and c.rigs()[0]["id"]
    for bad in (lambda: zwidth.Client("localhost:8080"), lambda: c.compare(["a"], format="xml"),
                lambda: c.watch("x", poll_s=0), lambda: zwidth.Client(url, timeout=float("nan")),
                lambda: zwidth.Client(url, timeout=None), lambda: zwidth.Client(url, timeout="5"),
                lambda: zwidth.Client("http://a b")):
        with pytest.raises(ValueError):
            bad()
    # Nothing listens on port 1: a clear ConnectionError, at once.
    with pytest.raises(ConnectionError, match="cannot reach the service"):
        zwidth.Client("http://127.0.0.1:1", timeout=5).rigs()


def test_every_call_of_the_client_is_a_route_of_the_openapi_document(monkeypatch):
    # Each method's request (method, path, query names) recorded without a
    # server, then looked up in api/openapi.json: a route renamed or a query
    # parameter dropped in the API fails here.
    doc = json.loads((EX.parent / "api/openapi.json").read_text())
    calls = []

    def record(self, method, path, body=None, query=None, raw=False):
        calls.append((method, path, sorted(k for k, v in (query or {}).items() if v is not None)))
        return {"state": "succeeded", "result": {}, "trials": []} if method == "GET" else {}

    monkeypatch.setattr(zwidth.Client, "_request", record)
    c = zwidth.Client("http://h")
    c.submit({"kind": "map"}, priority=1, rig="r", not_before_ms=5)
    c.status("e1")
    c.results("e1")
    c.trials("e1", scope=0)
    c.compare(["e1", "e2"], format="text")
    c.cancel("e1")
    c.rigs()
    c.watch("e1", progress=False)
    assert len(calls) == 8  # results and watch read the status once each
    for method, path, query in calls:
        route = re.sub(r"/e1(?=/|$)", "/{id}", path)
        op = doc["paths"].get(route, {}).get(method.lower())
        assert op is not None, f"{method} {route} is not in api/openapi.json"
        names = {p["name"] for p in op.get("parameters", []) if p["in"] == "query"}
        assert set(query) <= names, f"{method} {route}: {set(query) - names} not documented"


def _certificates(d):
    """A CA and a server certificate for 127.0.0.1 and localhost signed by
    it (openssl, as the CI installs it): (ca.pem, server.pem, server.key)."""
    run = lambda *a: subprocess.run(["openssl", *a], check=True, capture_output=True, cwd=d)
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    run("req", "-x509", *ec, "-keyout", "ca.key", "-out", "ca.pem", "-days", "1",
        "-subj", "/CN=zwidth test CA")
    run("req", *ec, "-keyout", "server.key", "-out", "server.csr", "-subj", "/CN=127.0.0.1")
    (d / "san.ext").write_text("subjectAltName=IP:127.0.0.1,DNS:localhost\n"
                               "extendedKeyUsage=serverAuth\n")
    run("x509", "-req", "-in", "server.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
        "-CAcreateserial", "-out", "server.pem", "-days", "1", "-extfile", "san.ext")
    return d / "ca.pem", d / "server.pem", d / "server.key"


def test_https_with_the_ca_given_by_argument_or_environment(tmp_path, monkeypatch):
    ca, cert, key = _certificates(tmp_path)
    db = tmp_path / "zwidth.db"
    p = subprocess.Popen([cli(), "serve", "--db", str(db), "--bind", "127.0.0.1:0",
                          "--tls-cert", str(cert), "--tls-key", str(key)],
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        m, deadline = None, time.monotonic() + 60
        while m is None and time.monotonic() < deadline:
            m = re.search(r"serving on (https://\S+)", p.stdout.readline())
        assert m, "the service did not start on https://"
        url = m.group(1)
        monkeypatch.delenv("ZWIDTH_CA_FILE", raising=False)
        assert zwidth.Client(url, ca_file=str(ca), timeout=10).rigs()[0]["id"]
        # The system's roots alone do not know this CA: refused by TLS.
        with pytest.raises(ConnectionError, match="cannot reach"):
            zwidth.Client(url, timeout=10).rigs()
        monkeypatch.setenv("ZWIDTH_CA_FILE", str(ca))
        assert zwidth.Client(url, timeout=10).rigs()[0]["id"]
        # A CA file that is not one: a ValueError naming it.
        with pytest.raises(ValueError, match="ca_file"):
            zwidth.Client(url, ca_file=str(db.parent / "zwidth.db.token"))
        with pytest.raises(ValueError, match="ca_file"):
            zwidth.Client(url, ca_file=3)
    finally:
        p.terminate()
        p.wait(timeout=30)


def test_compare_refuses_a_bare_string():
    """Issue 45: `compare("id")` asked for runs "i,d" and answered 404 "no
    experiment 0"; a bare string is refused before any request."""
    c = zwidth.Client("http://127.0.0.1:9")
    for bad, words in [("abc", "ids = 'abc'"), ([], "one or more"), (["a", 3], "one or more")]:
        with pytest.raises(ValueError) as e:
            c.compare(bad)
        assert words in str(e.value), str(e.value)
