"""deploy/docker-compose.yml, parsed and checked against docs/deploy.md and the repository (no Docker engine here)."""
import tomllib
from pathlib import Path, PurePosixPath

import pytest

from .deploy_files import DEPLOY, DOC, ROOT, compose, locked_version, parse_command

SERVICES = {"router", "robot", "controller", "console"}
SHAREDCTL_SERVICES = ("robot", "controller", "console")


def mounts(service: dict) -> dict[str, str]:
    """Container path -> host path of a service's bind mounts."""
    result = {}
    for volume in service.get("volumes", []):
        host, container, *_ = volume.split(":")
        result[container] = host
    return result


def host_path(host: str) -> Path | None:
    """A relative bind source is relative to deploy/ (the compose file's folder); absolute ones are the site's,
    and a bare name is a named volume."""
    return (DEPLOY / host).resolve() if host.startswith(".") else None


def test_the_services_are_the_documented_ones():
    assert set(compose()["services"]) == SERVICES
    doc = DOC.read_text()
    for name in SERVICES:
        assert f"`{name}`" in doc


def test_the_router_is_the_eclipse_zenoh_container_of_the_locked_zenoh_version():
    router = compose()["services"]["router"]
    assert router["image"] == f"eclipse/zenoh:{locked_version('eclipse-zenoh')}"
    assert router["image"] in DOC.read_text()
    flag, config = router["command"]
    assert flag == "-c"
    source = host_path(mounts(router)[config])
    assert source == DEPLOY / "zenoh" / "router.json5" and source.is_file()


def test_the_router_mounts_every_credential_file_its_config_names():
    router = compose()["services"]["router"]
    text = (DEPLOY / "zenoh" / "router.json5").read_text()
    named = {p for p in mounts(router) if p.startswith("/etc/sharedctl/credentials/")}
    for path in named:
        assert path in text, path
    for needed in ("passwords.txt", "ca.pem", "router.pem", "router-key.pem"):
        assert f"/etc/sharedctl/credentials/{needed}" in named


@pytest.mark.parametrize("name", SHAREDCTL_SERVICES)
def test_sharedctl_services_are_built_from_the_repository_dockerfile(name):
    service = compose()["services"][name]
    build = service["build"]
    context = (DEPLOY / build["context"]).resolve()
    assert context == ROOT and (context / build["dockerfile"]).is_file()
    assert service["image"].startswith("sharedctl:")


@pytest.mark.parametrize("name", SHAREDCTL_SERVICES)
def test_each_command_reads_a_settings_file_from_the_repository_and_parses(name):
    service = compose()["services"][name]
    command = service["command"]
    assert command[0] == name and command[1] == "--service-config"
    source = host_path(mounts(service)[command[2]])
    assert source == DEPLOY / "config" / f"{name}.toml" and source.is_file()
    args = parse_command([name, "--service-config", str(source)])
    assert args.command == name


@pytest.mark.parametrize("name,role,identity", [("robot", "robot", set()),
                                                ("controller", "controller", {"operators.toml"}),
                                                ("console", "operator", {"operator.signing-key.pem"})])
def test_each_service_sees_exactly_its_roles_credentials_and_every_file_its_settings_name(name, role, identity):
    service = compose()["services"][name]
    args = parse_command([name, "--service-config", str(DEPLOY / "config" / f"{name}.toml")])
    assert args.zenoh_config == f"/etc/sharedctl/credentials/{role}.json5"
    secrets = {PurePosixPath(p).name for p in mounts(service) if p.startswith("/etc/sharedctl/credentials/")}
    assert secrets == {f"{role}.json5", f"{role}.pem", f"{role}-key.pem", "ca.pem"} | identity
    named = [getattr(args, option, None) for option in ("zenoh_config", "operators", "signing_key")]
    assert {PurePosixPath(p).name for p in named if p} <= secrets       # what the settings name is there


def test_every_service_runs_as_the_owner_of_the_credentials():
    """make-credentials.sh writes keys and passwords mode 0600 and docs/deploy.md gives them to uid 990; with
    cap_drop ALL a root process could not read them (no CAP_DAC_OVERRIDE)."""
    assert "chown -R sharedctl:sharedctl /etc/sharedctl/credentials" in DOC.read_text()
    for name, service in compose()["services"].items():
        assert service.get("user") == "990:990", name


def test_every_service_stays_in_the_hosts_network_namespace_and_maps_no_port():
    for name, service in compose()["services"].items():
        assert service["network_mode"] == "host", name
        assert "ports" not in service, name


def test_every_service_runs_without_privileges():
    for name, service in compose()["services"].items():
        assert service["cap_drop"] == ["ALL"], name
        assert "no-new-privileges:true" in service["security_opt"], name
        assert service["read_only"] is True, name
        assert not service.get("privileged", False), name


def test_the_controller_alone_may_ask_for_realtime_priority():
    services = compose()["services"]
    controller = services["controller"]
    assert controller["cap_add"] == ["SYS_NICE"]
    assert controller["ulimits"]["rtprio"] >= 20                # SCHED_FIFO 20 (priority.py)
    assert controller["ulimits"]["nice"] >= 30                  # nice -10
    args = parse_command(["controller", "--service-config", str(DEPLOY / "config" / "controller.toml")])
    assert args.priority == "realtime"
    assert all("cap_add" not in s for n, s in services.items() if n != "controller")


def test_the_console_starts_only_on_demand_and_attaches_to_a_terminal():
    console = compose()["services"]["console"]
    assert console["profiles"] == ["console"] and console["stdin_open"] and console["tty"]
    assert "docker compose -f deploy/docker-compose.yml run --rm console" in DOC.read_text()


def test_long_running_services_restart_and_stop_by_sigterm():
    services = compose()["services"]
    for name in ("router", "robot", "controller"):
        assert services[name]["restart"] == "unless-stopped", name
    for name in SHAREDCTL_SERVICES:
        assert services[name]["stop_signal"] == "SIGTERM"


def test_the_controllers_checkpoint_is_on_a_named_volume_kept_across_restarts():
    """The settings file's checkpoint lies in a folder the read-only controller container can write and that
    outlives the container (a restarted controller resumes from it)."""
    import tomllib
    document = compose()
    folder = str(Path(tomllib.loads((DEPLOY / "config" / "controller.toml").read_text())["checkpoint"]).parent)
    assert mounts(document["services"]["controller"])[folder] == "controller-state"
    assert "controller-state" in document["volumes"]
    assert f"-m 0750 {folder}" in (DEPLOY / "Dockerfile").read_text()      # owned by the image's user


def test_every_relative_mount_exists_in_the_repository():
    for name, service in compose()["services"].items():
        for host in mounts(service).values():
            path = host_path(host)
            assert path is None or path.exists(), f"{name}: {host}"


def test_the_documented_compose_commands_use_this_file():
    doc = DOC.read_text()
    assert "docker compose -f deploy/docker-compose.yml up -d --build" in doc


def test_the_dockerfile_copies_only_what_exists_and_everything_the_build_reads():
    lines = (DEPLOY / "Dockerfile").read_text().splitlines()
    sources = [s for line in lines if line.startswith("COPY ") for s in line.split()[1:-1]]
    assert sources and all((ROOT / s).exists() for s in sources), sources
    assert any(line.startswith("USER ") and "root" not in line for line in lines)
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    needed = {"pyproject.toml", project["readme"], *project["license-files"], "sharedctl", "protocol", "services"}
    assert needed <= {s.split("/")[0] for s in sources}, needed - set(sources)


def test_the_image_installs_only_the_runtime_lock_checking_its_hashes():
    lines = (DEPLOY / "Dockerfile").read_text().splitlines()
    installs = [line for line in lines if "pip install" in line]
    assert installs[0].split() == ["RUN", "pip", "install", "--require-hashes", "-r", "requirements/runtime.lock"]
    assert all("--no-deps" in line and "--no-build-isolation" in line for line in installs[1:])
    assert not any("test.lock" in line or "requirements.lock" in line for line in lines)
    runtime = (ROOT / "requirements" / "runtime.lock").read_text()
    assert "\npytest==" not in runtime and "\nmatplotlib==" not in runtime


def test_every_credential_file_a_service_mounts_is_one_make_credentials_writes(tmp_path):
    from sharedctl.services.security.credentials import generate
    from sharedctl.services.security.credentials_command import write_site_configs

    site = generate(tmp_path / "credentials")
    write_site_configs(site, "tls/127.0.0.1:7447")
    written = {p.name for p in site.directory.iterdir()}
    for name, service in compose()["services"].items():
        for host in mounts(service).values():
            if host.startswith("/etc/sharedctl/credentials/"):
                assert PurePosixPath(host).name in written, (name, host)
