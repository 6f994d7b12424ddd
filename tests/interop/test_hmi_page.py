"""The browser HMI's files as a browser fetches them over plain HTTP: the
page, its main module, and the plotting library embedded at build time
(the developer view's uPlot, which the package build takes from a file,
not from npm). Run against the host build here and against the armhf
build under qemu-arm (tests/armhf.sh)."""

from __future__ import annotations

import urllib.request

from test_mavlink2rest import GENEROUS_S, http_addr


def get(addr: str, path: str) -> tuple[int, str, bytes]:
    with urllib.request.urlopen(f"http://{addr}{path}", timeout=GENEROUS_S) as r:
        return r.status, r.headers.get("Content-Type", ""), r.read()


def test_the_page_its_module_and_the_plotting_library_are_served(make_vehicle):
    addr = http_addr(make_vehicle())
    status, ctype, body = get(addr, "/")
    assert status == 200 and ctype.startswith("text/html"), (status, ctype)
    assert b'<script type="module" src="/js/main.js">' in body, body[:400]
    status, ctype, body = get(addr, "/js/main.js")
    assert status == 200 and "javascript" in ctype, (status, ctype)
    assert b"import" in body
    status, ctype, body = get(addr, "/vendor/uPlot.esm.js")
    assert status == 200 and "javascript" in ctype, (status, ctype)
    # uPlot's ES module exports its constructor as the default export.
    assert b"export default uPlot" in body or b"export { uPlot as default }" in body, body[-200:]
    status, ctype, _ = get(addr, "/vendor/uPlot.min.css")
    assert status == 200 and ctype.startswith("text/css"), (status, ctype)
