# lrf-emulator in a container: the virtual sensors served over TCP.
# A pty cannot leave a container, so both sensors are published as TCP ports
# bound to 0.0.0.0: the URG-04LX speaks SCIP 2.0 on 10940 (as its Ethernet
# models do) and the LMS200 sends its telegrams on 10941 (what a
# serial-to-Ethernet converter gives). docs/interop.md shows how to bridge a
# port back to a device file on the host with socat.
#
# glibc x86_64 base: embreex publishes no musl or aarch64 wheels.
FROM python:3.11-slim-bookworm

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

WORKDIR /src
COPY pyproject.toml README.md ./
COPY emulator ./emulator
COPY protocols ./protocols
COPY scenes ./scenes
RUN pip install --no-cache-dir . \
    && useradd --system --uid 10001 --user-group --create-home --home-dir /home/lrf \
        --shell /usr/sbin/nologin lrf

# Numeric, so that a host or an orchestrator can check it is not root.
USER 10001:10001
WORKDIR /home/lrf

# numba compiles the physical model's and the plumes' kernels on first use (10-30 s): compile them
# now into a cache the sensor user owns, so a container's first scans are on time.
ENV NUMBA_CACHE_DIR=/home/lrf/.numba-cache
RUN python -c "from emulator.sensors.physical.warm import compile_kernels; compile_kernels()"

EXPOSE 10940/tcp 10941/tcp

ENTRYPOINT ["lrf-emulator"]
CMD ["serve", "railway", "--endpoint", "urg=tcp:0.0.0.0:10940", "--endpoint", "lms=tcp:0.0.0.0:10941"]
