"""Sans-I/O device protocols: bytes and time in, bytes out. No sockets, files or physics."""
