"""Drive the service through a client generated from api/openapi.json
(openapi-python-client): submit -> poll -> result -> compare, and a bad
request answered as a ProblemBody naming the field. Usage:
    PYTHONPATH=<dir with zwidth_client> python3 client_check.py URL TOKEN
Prints 'client: N passed, 0 failed' or raises."""
import json
import sys
import time

from zwidth_client import Client
from zwidth_client.api.default import compare_runs, healthz, list_, show, submit
from zwidth_client.models import (
    Comparison,
    ExperimentPage,
    ExperimentSpecMap,
    ExperimentView,
    HealthView,
    Preset,
    ProblemBody,
    SceneSpec,
)

url = sys.argv[1]
# Writes need the user token (serve made it next to its database).
client = Client(
    base_url=url,
    raise_on_unexpected_status=True,
    headers={"Authorization": f"Bearer {sys.argv[2]}"},
)
passed = 0


def check(cond, what):
    global passed
    if not cond:
        raise SystemExit(f"client check failed: {what}")
    passed += 1


check(isinstance(healthz.sync(client=client), HealthView), "healthz")
scene = SceneSpec.from_dict(json.load(open("examples/linear_1khz.json")))
ids = []
k_widths = []
for b in ([2.0], [4.0]):
    body = ExperimentSpecMap(kind="map", scene=scene, accuracy=Preset.DRAFT, b=b)
    r = submit.sync_detailed(client=client, body=body, priority=1000)
    check(r.status_code == 202 and isinstance(r.parsed, ExperimentView), f"submit: {r.status_code} {r.content[:300]!r}")
    ids.append(r.parsed.id)
for i in ids:
    deadline = time.time() + 120
    while True:
        v = show.sync(i, client=client)
        if v.state in ("succeeded", "failed", "cancelled"):
            break
        check(time.time() < deadline, f"{i} still {v.state}")
        time.sleep(0.1)
    check(v.state == "succeeded", f"{i} ended {v.state}: {v.error}")
    check(v.result is not None, f"{i} has a result")
    k_widths.append(v.to_dict()["result"]["k_width"])
page = list_.sync(client=client, limit=10)
check(isinstance(page, ExperimentPage) and len(page.experiments) >= 2, "list")
c = compare_runs.sync(client=client, runs=",".join(ids))
check(isinstance(c, Comparison) and len(c.rows) == 2, f"compare: {c}")
# The comparison reports each run's own K-width (read from its result above).
check([r.k_width for r in c.rows] == k_widths, f"compare rows {[r.k_width for r in c.rows]} vs results {k_widths}")
bad = submit.sync(client=client, body=ExperimentSpecMap.from_dict({"kind": "map", "scene": {"device": {"mass": -1}}}))
check(isinstance(bad, ProblemBody) and bad.status == 422 and bad.field == "scene.device.mass", f"bad body: {bad}")
print(f"client: {passed} passed, 0 failed")
