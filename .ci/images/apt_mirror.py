"""The Debian mirror this machine's apt takes SUITE from (issue 45 item 13):
the first `deb` source of /etc/apt/sources.list, sources.list.d/*.list
(one-line format) and sources.list.d/*.sources (deb822) whose suites
include SUITE and which is not the security archive; Debian's own
(http://deb.debian.org/debian) when there is none. Prints its URI.

usage: python3 .ci/images/apt_mirror.py SUITE [APT_DIR]   (APT_DIR: /etc/apt)
"""
import glob
import os
import sys

DEFAULT = "http://deb.debian.org/debian"


def one_line(text):
    """(types, uris, suites) of each `deb [opts] URI SUITE COMPONENTS…` line."""
    for line in text.splitlines():
        words = line.split("#", 1)[0].split()
        if len(words) < 3 or words[0] != "deb":
            continue
        rest = words[1:]
        if rest[0].startswith("["):
            # Options in brackets, possibly over several words.
            while rest and not rest[0].endswith("]"):
                rest = rest[1:]
            rest = rest[1:]
        if len(rest) >= 2:
            yield ["deb"], [rest[0]], [rest[1]]


def deb822(text):
    """(types, uris, suites) of each stanza of a .sources file."""
    for stanza in text.split("\n\n"):
        fields, key = {}, None
        for line in stanza.splitlines():
            if line.startswith("#"):
                continue
            if line[:1] in (" ", "\t") and key:
                fields[key] += " " + line.strip()
            elif ":" in line:
                key, value = line.split(":", 1)
                key = key.strip().lower()
                fields[key] = value.strip()
        if fields.get("enabled", "yes").lower() == "no":
            continue
        yield fields.get("types", "").split(), fields.get("uris", "").split(), \
            fields.get("suites", "").split()


def mirror(suite, apt="/etc/apt"):
    found = []
    files = [os.path.join(apt, "sources.list")] + sorted(glob.glob(os.path.join(apt, "sources.list.d", "*.list")))
    for f in files:
        if os.path.isfile(f):
            found += one_line(open(f, encoding="utf-8", errors="replace").read())
    for f in sorted(glob.glob(os.path.join(apt, "sources.list.d", "*.sources"))):
        found += deb822(open(f, encoding="utf-8", errors="replace").read())
    for types, uris, suites in found:
        if "deb" in types and suite in suites:
            for uri in uris:
                if "security" not in uri:
                    return uri.rstrip("/")
    return DEFAULT


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    print(mirror(sys.argv[1], *sys.argv[2:3]))
