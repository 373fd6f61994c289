"""Fixtures shared by every test folder."""

from __future__ import annotations

import pathlib
import socket
from dataclasses import dataclass

import pytest


@dataclass(frozen=True)
class S3Server:
    """A local S3-compatible server; credentials are dummies it accepts."""

    endpoint_url: str

    @property
    def storage_options(self) -> dict:
        """The fsspec/s3fs options that reach this server."""
        return {"endpoint_url": self.endpoint_url, "key": "x", "secret": "x"}

    def upload(self, local: pathlib.Path, bucket: str) -> str:
        """Copy the directory ``local`` to a new ``bucket`` and return its URL, ``s3://<bucket>/root``."""
        import s3fs

        fs = s3fs.S3FileSystem(key="x", secret="x", client_kwargs={"endpoint_url": self.endpoint_url})
        fs.mkdir(bucket)
        fs.put(f"{local}/", f"{bucket}/root/", recursive=True)
        return f"s3://{bucket}/root"


@pytest.fixture(scope="session")
def s3_server():
    """One moto server on 127.0.0.1 for the whole session; tests keep to their own buckets."""
    moto_server = pytest.importorskip("moto.server")
    pytest.importorskip("s3fs")
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    server = moto_server.ThreadedMotoServer(ip_address="127.0.0.1", port=port)
    server.start()
    try:
        yield S3Server(f"http://127.0.0.1:{port}")
    finally:
        server.stop()
