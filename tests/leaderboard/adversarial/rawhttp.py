"""Raw HTTP over a socket, for requests that ordinary clients refuse to send (standard library only)."""

from __future__ import annotations

import json
import socket
from urllib.parse import urlsplit

#: How long a test waits for the server to say anything: far above any deadline the tests set.
READ_TIMEOUT_S = 20.0


def connect(url: str) -> socket.socket:
    parts = urlsplit(url)
    return socket.create_connection((parts.hostname, parts.port), timeout=READ_TIMEOUT_S)


def upload_head(token: str, length: int, *, expect_continue: bool = False) -> bytes:
    """The request line and headers of an upload of ``length`` bytes."""
    expect = "Expect: 100-continue\r\n" if expect_continue else ""
    return (f"POST /api/submissions HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {token}\r\n"
            f"Content-Type: application/json\r\nContent-Length: {length}\r\n{expect}\r\n").encode()


def read_until_closed(sock: socket.socket) -> bytes:
    """Everything the server sends until it closes (a reset counts as closed)."""
    chunks = []
    while True:
        try:
            chunk = sock.recv(65536)
        except ConnectionResetError:
            break
        if not chunk:
            break
        chunks.append(chunk)
    return b"".join(chunks)


def read_head(sock: socket.socket) -> bytes:
    """One answer's status line and headers (nothing after them is consumed)."""
    head = b""
    while not head.endswith(b"\r\n\r\n"):
        byte = sock.recv(1)
        if not byte:
            break
        head += byte
    return head


def read_answer(sock: socket.socket) -> bytes:
    """One whole answer: its head, then as many bytes as its Content-Length says."""
    head = read_head(sock)
    length = 0
    for line in head.split(b"\r\n"):
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length":
            length = int(value)
    body = b""
    while len(body) < length and (chunk := sock.recv(length - len(body))):
        body += chunk
    return head + body


def status_of(answer: bytes) -> int:
    return int(answer.split(b" ", 2)[1]) if answer.startswith(b"HTTP/") else 0


def json_body(answer: bytes) -> dict:
    return json.loads(answer.split(b"\r\n\r\n", 1)[1])
