"""Write ``nginx.conf`` and ``ulnef.conf`` for other replica addresses and another listen address.

Only the ``server`` lines of ``upstream ulnef`` and the ``listen`` line change (each replica keeps
the parameters of the first line, ``max_fails`` ...); everything else is the shipped file. Standard
library only. Two local replicas behind nginx on port 8080::

    ulnef serve --port 8001 & ulnef serve --port 8002 &
    python deploy/nginx/render.py /tmp/ulnef-nginx 127.0.0.1:8001 127.0.0.1:8002
    nginx -p /tmp/ulnef-nginx/ -c /tmp/ulnef-nginx/nginx.conf -g 'daemon off;'
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
UPSTREAM = re.compile(r"^(upstream ulnef \{\n)(.*?)(^\})", re.M | re.S)
SERVER = re.compile(r"^([ \t]*)server (\S+)(.*;)\n", re.M)
LISTEN = re.compile(r"^([ \t]*)listen \S+;$", re.M)


def render(replicas: list[str], listen: str = "127.0.0.1:8080", workers: str = "auto") -> dict[str, str]:
    """{file name: text} of the two files with ``replicas`` (``host:port`` each) as the upstream
    servers, ``listen`` as the address and ``workers`` as ``worker_processes``. Raises ValueError
    when the shipped files no longer have the lines this rewrites."""
    if not replicas or any(not re.fullmatch(r"[\w.\-\[\]:]+:\d+", r) for r in replicas):
        raise ValueError(f"replicas must be host:port addresses, got {replicas!r}")
    site = (HERE / "ulnef.conf").read_text()
    block = UPSTREAM.search(site)
    servers = list(SERVER.finditer(block.group(2))) if block else []
    if not servers:
        raise ValueError("ulnef.conf: no `server` line in `upstream ulnef { ... }`")
    indent, params = servers[0].group(1), servers[0].group(3)
    lines = "".join(f"{indent}server {r}{params}\n" for r in replicas)
    body = block.group(2)
    body = body[: servers[0].start()] + lines + body[servers[-1].end() :]
    site = site[: block.start(2)] + body + site[block.end(2) :]
    site, n = LISTEN.subn(lambda m: f"{m.group(1)}listen {listen};", site)
    if n != 1:
        raise ValueError(f"ulnef.conf: expected one `listen` line, found {n}")
    main, n = re.subn(r"^worker_processes \S+;$", f"worker_processes {workers};",
                      (HERE / "nginx.conf").read_text(), flags=re.M)  # fmt: skip
    if n != 1:
        raise ValueError(f"nginx.conf: expected one `worker_processes` line, found {n}")
    return {"nginx.conf": main, "ulnef.conf": site}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="folder to write nginx.conf and ulnef.conf into")
    parser.add_argument("replicas", nargs="+", help="replica addresses, host:port")
    parser.add_argument("--listen", default="127.0.0.1:8080", help="address nginx listens on")
    args = parser.parse_args(argv)
    try:
        files = render(args.replicas, args.listen)
    except ValueError as e:
        print(f"render.py: {e}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (args.out / name).write_text(text)
    print(f"nginx -p {args.out.resolve()}/ -c {args.out.resolve() / 'nginx.conf'} -g 'daemon off;'")
    return 0


if __name__ == "__main__":
    sys.exit(main())
