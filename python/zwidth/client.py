"""The zwidth service from Python: submit, watch, read and cancel
experiments, list rigs (docs/service.md, api/openapi.json).

    >>> c = zwidth.Client("http://127.0.0.1:8080", token=open("zwidth.db.token").read().strip())
    >>> e = c.submit({"kind": "compare", "accuracy": "draft"})
    >>> done = c.watch(e["id"])           # a progress bar (tqdm when installed)
    >>> c.results(e["id"])                # the result, as GET /v1/experiments/{id} has it

Standard library only (urllib). A refusal (a 4xx or 5xx problem+json,
RFC 9457) raises ApiError with its status, title, detail and the field to
blame (a ValueError); a service that cannot be reached raises
ConnectionError, one that does not answer in `timeout` s TimeoutError.
"""

from __future__ import annotations

import json
import math
import socket
import sys
import time
import urllib.parse
from typing import Any, Dict, Iterable, List, Optional, Union

from ._progress import Bar

__all__ = ["ApiError", "Client", "ENDED"]

#: States after which an experiment changes no more (docs/service.md).
ENDED = frozenset({"succeeded", "failed", "cancelled"})


class ApiError(ValueError):
    """The service refused a request: `status` (HTTP), `title`, `detail`,
    and `field` (the offending field, or None)."""

    def __init__(self, status: int, title: str, detail: str, field: Optional[str] = None):
        self.status, self.title, self.detail, self.field = status, title, detail, field
        where = f" [{field}]" if field else ""
        super().__init__(f"{status} {title}{where}: {detail}")


class Client:
    """A client of one zwidth service at `url`; `token` (the user token the
    service made next to its database) is needed for writes. An https://
    service is trusted by the system's roots, plus the PEM CA certificates
    in `ca_file` (default: the file named by ZWIDTH_CA_FILE, as for the CLI
    and the agent)."""

    def __init__(self, url: str = "http://127.0.0.1:8080", token: Optional[str] = None,
                 timeout: float = 30.0, ca_file: Optional[str] = None):
        if not isinstance(url, str) or not url.startswith(("http://", "https://")) or any(
                c.isspace() for c in url):
            raise ValueError(f"url = {url!r} is not allowed: must start with http:// or https://, "
                             "without spaces")
        try:
            ok = isinstance(timeout, (int, float)) and math.isfinite(timeout) and timeout > 0
        except TypeError:
            ok = False
        if not ok:
            raise ValueError(f"timeout = {timeout!r} is not allowed: must be a finite number > 0 (s)")
        self.url = url.rstrip("/")
        self.token = token
        self.timeout = timeout
        self._tls = None
        if ca_file is None:
            import os
            ca_file = os.environ.get("ZWIDTH_CA_FILE") or None
        if ca_file is not None:
            import ssl
            if not isinstance(ca_file, (str, bytes)) and not hasattr(ca_file, "__fspath__"):
                raise ValueError(f"ca_file = {ca_file!r} is not allowed: must be a path to a PEM "
                                 "file of CA certificates")
            try:
                self._tls = ssl.create_default_context(cafile=ca_file)
            except (OSError, ssl.SSLError) as e:
                raise ValueError(f"ca_file = {ca_file!r} is not allowed: not a readable PEM file of "
                                 f"CA certificates ({e})") from None

    def _request(self, method: str, path: str, body: Any = None,
                 query: Optional[Dict[str, Any]] = None, raw: bool = False) -> Any:
        # Imported here: `import zwidth` need not load the HTTP stack (22 ms).
        import urllib.error
        import urllib.request

        url = self.url + path
        if query:
            url += "?" + urllib.parse.urlencode({k: v for k, v in query.items() if v is not None})
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(url, data=data, method=method)
        if data is not None:
            req.add_header("content-type", "application/json")
        if self.token:
            req.add_header("authorization", f"Bearer {self.token}")
        try:
            with urllib.request.urlopen(req, timeout=self.timeout, context=self._tls) as r:
                payload = r.read()
        except urllib.error.HTTPError as e:
            payload = e.read()
            try:
                p = json.loads(payload)
            except ValueError:
                p = {}
            raise ApiError(e.code, p.get("title", e.reason or "error"),
                           p.get("detail", payload.decode(errors="replace")[:500]),
                           p.get("field")) from None
        except urllib.error.URLError as e:
            raise ConnectionError(f"{self.url}: cannot reach the service ({e.reason})") from None
        except (TimeoutError, socket.timeout):
            raise TimeoutError(f"{self.url}: no answer within {self.timeout} s") from None
        return payload.decode() if raw else json.loads(payload)

    def submit(self, spec: Dict[str, Any], *, priority: Optional[int] = None,
               rig: Optional[str] = None, not_before_ms: Optional[int] = None) -> Dict[str, Any]:
        """Queue an experiment (`{"kind": "map" | "compare" | "sweep" |
        "tune", …}`); the stored experiment with its cost estimate."""
        return self._request("POST", "/v1/experiments", spec,
                             {"priority": priority, "rig": rig, "not_before_ms": not_before_ms})

    def status(self, id: str) -> Dict[str, Any]:  # noqa: A002 - the API's word
        """State, progress, spec, result or error of one experiment."""
        return self._request("GET", f"/v1/experiments/{urllib.parse.quote(id)}")

    def watch(self, id: str, *, poll_s: float = 0.5, progress: bool = True,  # noqa: A002
              timeout_s: Optional[float] = None) -> Dict[str, Any]:
        """Poll until the experiment ends (succeeded, failed or cancelled);
        its last status. With `progress`, a bar on stderr (tqdm's when it is
        installed). `timeout_s` gives up with TimeoutError."""
        if not (isinstance(poll_s, (int, float)) and math.isfinite(poll_s) and poll_s > 0):
            raise ValueError(f"poll_s = {poll_s!r} is not allowed: must be a finite number > 0 (s)")
        bar = Bar(id[:12]) if progress else None
        start = time.monotonic()
        try:
            while True:
                s = self.status(id)
                if bar:
                    bar.update((s.get("progress") or {}).get("fraction", 0.0), s["state"])
                if s["state"] in ENDED:
                    return s
                if timeout_s is not None and time.monotonic() - start > timeout_s:
                    raise TimeoutError(f"experiment {id} still {s['state']} after {timeout_s} s")
                time.sleep(poll_s)
        finally:
            if bar:
                bar.close()

    def results(self, id: str) -> Any:  # noqa: A002
        """The result of a succeeded experiment; ApiError-free ValueError
        naming the state otherwise."""
        s = self.status(id)
        if s["state"] != "succeeded":
            raise ValueError(f"id = {id} is not allowed: its state is {s['state']}, not succeeded"
                             + (f" ({s['error']})" if s.get("error") else ""))
        return s["result"]

    def trials(self, id: str, *, scope: Optional[int] = None) -> List[Dict[str, Any]]:  # noqa: A002
        """Every stored trial of an experiment, in the order they finished."""
        out: List[Dict[str, Any]] = []
        while True:
            page = self._request("GET", f"/v1/experiments/{urllib.parse.quote(id)}/trials",
                                 query={"scope": scope, "offset": len(out), "limit": 1000})
            rows = page["trials"] if isinstance(page, dict) else page
            out.extend(rows)
            if len(rows) < 1000:
                return out

    def compare(self, ids: Iterable[str], *, format: str = "json") -> Union[Dict[str, Any], str]:  # noqa: A002
        """Runs side by side (`GET /v1/compare`): a dict, or the text table
        or SVG with `format="text"` or `"svg"`."""
        if format not in ("json", "text", "svg"):
            raise ValueError(f"format = {format} is not allowed: json, text or svg")
        if isinstance(ids, (str, bytes)):
            # A bare id would be read letter by letter ("abc" as a, b, c).
            raise ValueError(f"ids = {ids!r} is not allowed: a list of experiment ids, "
                             f"e.g. [{ids!r}, …]")
        ids = list(ids)
        bad = [i for i in ids if not isinstance(i, str) or not i]
        if not ids or bad:
            raise ValueError(f"ids = {ids!r} is not allowed: one or more experiment ids (str)")
        q = {"runs": ",".join(ids), "format": format}
        return self._request("GET", "/v1/compare", query=q, raw=format != "json")

    def cancel(self, id: str) -> Dict[str, Any]:  # noqa: A002
        """Cancel a queued or running experiment (409 ApiError once ended)."""
        return self._request("POST", f"/v1/experiments/{urllib.parse.quote(id)}/cancel")

    def rigs(self) -> List[Dict[str, Any]]:
        """The rigs with their capabilities, windows and queues."""
        r = self._request("GET", "/v1/rigs")
        return r["rigs"] if isinstance(r, dict) and "rigs" in r else r
