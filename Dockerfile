# The urdaemon image used by compose.yaml: the package installed from this checkout, run from /app
# so that the relative path configs/dual_robot_ursim.yaml resolves.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

WORKDIR /app

# Only what the build and the daemon need (no .venv, caches or tests from the host):
# pyproject.toml and README.md (the project's readme) for the build, the package, the resources
# the wheel ships, and the cell files.
COPY pyproject.toml README.md ./
COPY urdaemon ./urdaemon
COPY resources ./resources
COPY configs ./configs

RUN pip install .

# Zenoh (configs/dual_robot_ursim.yaml listens on tcp/0.0.0.0:7447) and the robots' connect-back
# ports: alice 50001-50004, bob 50011-50014.
EXPOSE 7447 50001-50004 50011-50014

CMD ["urdaemon", "serve", "--config", "configs/dual_robot_ursim.yaml"]
