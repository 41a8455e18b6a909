#!/usr/bin/env python3
"""A TCP proxy that delays every byte by a fixed time in each direction: the added delay of the
shaped-link table (docs/performance.md, "Links that are not loopback") where the kernel has no
netem. Each connection accepted on --listen is forwarded to --to; what is read from one side is
written to the other no sooner than --delay-ms after it was read, in order, with at most
--window bytes in flight per direction (the proxy never reads further ahead, so a slow receiver
still holds the sender back). Threads with nanosecond sleeps, not an event loop: an event loop's
timers have a resolution of a millisecond.

    docs/tools/delay_proxy.py --listen 127.0.0.1:17448 --to 10.214.0.1:17447 --delay-ms 0.5

Prints "listening" once it accepts connections; runs until killed.
"""
import argparse
import collections
import socket
import sys
import threading
import time

CHUNK = 1 << 16


def endpoint(text):
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit():
        raise argparse.ArgumentTypeError(f"{text}: expected host:port")
    return host, int(port)


def forward(src, dst, delay, window):
    """Copies src to dst, each chunk written `delay` seconds after it was read."""
    queue = collections.deque()
    cond = threading.Condition()
    state = {"bytes": 0, "eof": False}

    def read():
        try:
            while True:
                with cond:
                    while state["bytes"] >= window:
                        cond.wait()
                data = src.recv(CHUNK)
                with cond:
                    queue.append((time.monotonic() + delay, data))
                    state["bytes"] += len(data)
                    cond.notify_all()
                if not data:
                    return
        except OSError:
            with cond:
                queue.append((time.monotonic(), b""))
                cond.notify_all()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        while True:
            with cond:
                while not queue:
                    cond.wait()
                due, data = queue.popleft()
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            if not data:
                break
            dst.sendall(data)
            with cond:
                state["bytes"] -= len(data)
                cond.notify_all()
    except OSError:
        pass
    for s, how in ((dst, socket.SHUT_WR), (src, socket.SHUT_RD)):
        try:
            s.shutdown(how)
        except OSError:
            pass


def serve(conn, to, delay, window):
    try:
        upstream = socket.create_connection(to)
    except OSError as e:
        print(f"delay_proxy: cannot connect to {to[0]}:{to[1]}: {e}", file=sys.stderr)
        conn.close()
        return
    for s in (conn, upstream):
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    threads = [
        threading.Thread(target=forward, args=(conn, upstream, delay, window), daemon=True),
        threading.Thread(target=forward, args=(upstream, conn, delay, window), daemon=True),
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    conn.close()
    upstream.close()


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--listen", type=endpoint, required=True)
    p.add_argument("--to", type=endpoint, required=True)
    p.add_argument("--delay-ms", type=float, required=True)
    p.add_argument("--window", type=int, default=4 << 20, help="bytes in flight per direction")
    a = p.parse_args()
    if a.delay_ms < 0:
        p.error("--delay-ms must be ≥ 0")
    server = socket.create_server(a.listen)
    print("listening", flush=True)
    while True:
        conn, _ = server.accept()
        threading.Thread(target=serve, args=(conn, a.to, a.delay_ms / 1000, a.window), daemon=True).start()


if __name__ == "__main__":
    main()
