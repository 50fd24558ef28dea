"""Link security (comms.link_security): MAC, anti-replay window, resynchronisation, key files, the uplink
that cannot lose a command silently, and the loopback-only telecommand binding."""
from __future__ import annotations

import os
import socket
import stat

import pytest

from comms.dictionary import DICTIONARY
from comms.link_security import (BAD_MAC, MAC_LEN, OUTSIDE_WINDOW, REPLAY, SPI_TC, SPI_TM, UNAUTHENTICATED,
                               KeyFileError, SecurityAssociation, SecurityError, SequenceFile, downlink_receiver,
                               load_key_file, uplink_receiver, write_key_file)
from fsw.telecommand import CommandDispatcher
from comms.telecommand import encode_command
from fsw.telemetry import TelemetrySender
from comms.telemetry import decode_tm_packet

KEY = bytes(range(32))
RESYNC = DICTIONARY.command("SEC_RESYNC").opcode


def _flight_dispatcher(window: int = 16, port: int | None = None, **kwargs) -> CommandDispatcher:
    dispatcher = CommandDispatcher(DICTIONARY, None, port=port,
                                   security=uplink_receiver(KEY, window, resync_opcode=RESYNC), **kwargs)
    dispatcher.register("NOOP", lambda: None)
    dispatcher.register("SET_MODE", lambda mode: None)
    dispatcher.register("RESET_COUNTERS", dispatcher.reset_counters)
    return dispatcher


def _ground() -> SecurityAssociation:
    return SecurityAssociation(KEY, SPI_TC)


def test_protect_then_unprotect_gives_back_the_plain_packet_and_every_altered_byte_is_refused() -> None:
    plain = encode_command(DICTIONARY, "SET_MODE", ["POINTING"], seq_count=7)
    secured = _ground().protect(plain, sn=5)
    assert len(secured) == len(plain) + 22
    receiver = uplink_receiver(KEY)
    assert receiver.unprotect(secured) == (plain, 5)
    for i in range(len(secured) - 2):  # every byte but the CRC (which would make it a format error)
        forged = bytearray(secured)
        forged[i] ^= 0x01
        from fastcrc import crc16

        forged[-2:] = crc16.ibm_3740(bytes(forged[:-2])).to_bytes(2, "big")  # an attacker fixes the CRC
        with pytest.raises(SecurityError) as exc:
            uplink_receiver(KEY).unprotect(bytes(forged))
        assert exc.value.reason in (BAD_MAC, UNAUTHENTICATED, "format"), i


def test_other_key_and_other_direction_are_refused() -> None:
    plain = encode_command(DICTIONARY, "NOOP")
    with pytest.raises(SecurityError, match="MAC") as exc:
        uplink_receiver(KEY).unprotect(SecurityAssociation(bytes(32), SPI_TC).protect(plain, sn=1))
    assert exc.value.reason == BAD_MAC
    # a telemetry packet signed by the flight software is no telecommand (own SPI, own derived key)
    tm = TelemetrySender(DICTIONARY, port=None, security=SecurityAssociation(KEY, SPI_TM)).send_channels("HK")
    with pytest.raises(SecurityError) as exc:
        uplink_receiver(KEY).unprotect(tm)
    assert exc.value.reason == UNAUTHENTICATED
    assert decode_tm_packet(DICTIONARY, downlink_receiver(KEY).unprotect(tm)[0]).packet == "HK"


def test_unauthenticated_forged_and_replayed_commands_are_refused_and_counted_by_reason() -> None:
    """The issue's attacks: plain commands, a forged MAC, one NOOP replayed 481 times."""
    dispatcher = _flight_dispatcher()
    ground = _ground()
    assert not dispatcher.handle_datagram(encode_command(DICTIONARY, "SET_MODE", ["SAFE"])).accepted
    forged = bytearray(ground.protect(encode_command(DICTIONARY, "SET_MODE", ["SAFE"]), sn=1))
    forged[-3] ^= 0xFF  # last MAC byte
    from fastcrc import crc16

    forged[-2:] = crc16.ibm_3740(bytes(forged[:-2])).to_bytes(2, "big")
    assert dispatcher.handle_datagram(bytes(forged)).error == "SECURITY"
    noop = ground.protect(encode_command(DICTIONARY, "NOOP", seq_count=1), sn=1)
    results = [dispatcher.handle_datagram(noop) for _ in range(481)]
    assert [r.accepted for r in results] == [True] + [False] * 480
    assert {r.error for r in results[1:]} == {"SECURITY"}
    hk = dispatcher.hk_values()
    assert (hk["tc_accepted"], hk["tc_sec_unauthenticated"], hk["tc_sec_bad_mac"], hk["tc_sec_replay"]) == (1, 1, 1, 480)
    assert hk["tc_sec_last_sn"] == 1


def test_reset_counters_does_not_erase_the_security_evidence() -> None:
    dispatcher = _flight_dispatcher()
    ground = _ground()
    replayed = ground.protect(encode_command(DICTIONARY, "NOOP"), sn=1)
    for _ in range(3024):
        dispatcher.handle_datagram(replayed)
    reset = ground.protect(encode_command(DICTIONARY, "RESET_COUNTERS", seq_count=1), sn=2)
    assert dispatcher.handle_datagram(reset).accepted
    hk = dispatcher.hk_values()
    assert hk["tc_rejected"] == 0  # the ordinary counters are reset ...
    assert hk["tc_sec_replay"] == 3023 and hk["tc_sec_last_sn"] == 2  # ... the security ones are not


def test_window_and_authenticated_resynchronisation() -> None:
    dispatcher = _flight_dispatcher(window=16)
    ground = _ground()

    def send(command: str, sn: int) -> bool:
        return dispatcher.handle_datagram(ground.protect(encode_command(DICTIONARY, command), sn=sn)).accepted

    assert send("NOOP", 3)  # a gap within the window: commands lost on the way
    assert not send("NOOP", 3 + 17)  # too far ahead
    assert dispatcher.security.counters[OUTSIDE_WINDOW] == 1
    assert send("SEC_RESYNC", 1000)  # the resync command may jump ...
    assert dispatcher.hk_values()["tc_sec_resyncs"] == 1
    assert send("NOOP", 1001)
    assert not send("SEC_RESYNC", 500)  # ... but never back (that would reopen SNs to replay)
    assert dispatcher.security.counters[REPLAY] == 1
    # a resync signed with another key is refused like any forgery
    other = SecurityAssociation(bytes(32), SPI_TC).protect(encode_command(DICTIONARY, "SEC_RESYNC"), sn=5000)
    assert not dispatcher.handle_datagram(other).accepted and dispatcher.security.last_sn == 1001


def test_key_files_are_private_and_checked(tmp_path) -> None:
    path = tmp_path / "link.key"
    key = write_key_file(path)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and load_key_file(path) == key and len(key) == 32
    with pytest.raises(FileExistsError):
        write_key_file(path)  # never overwrites a key
    os.chmod(path, 0o640)
    with pytest.raises(KeyFileError, match="readable by others"):
        load_key_file(path)
    bad = tmp_path / "bad.key"
    bad.write_text("not hex")
    os.chmod(bad, 0o600)
    with pytest.raises(KeyFileError, match="bad.key: not a key file"):
        load_key_file(bad)
    with pytest.raises(KeyFileError, match="cannot read"):
        load_key_file(tmp_path / "missing.key")
    with pytest.raises(KeyFileError, match="regular file"):
        os.chmod(tmp_path, 0o700)
        load_key_file(tmp_path)


def test_sequence_file_is_shared_by_every_sender_and_only_increases(tmp_path) -> None:
    a, b = SequenceFile.beside(tmp_path / "k.key"), SequenceFile.beside(tmp_path / "k.key")
    assert [a.advance(), b.advance(), a.advance()] == [1, 2, 3]
    assert b.advance(at_least=100) == 101 and a.peek() == 101


def test_a_junk_flood_cannot_make_a_command_disappear_silently() -> None:
    """20 000 junk datagrams around one legitimate SET_MODE into a small socket buffer: every datagram is
    either handled or counted as dropped by the kernel (SO_RXQ_OVFL), so the command was either
    executed or its loss shows in housekeeping."""
    dispatcher = _flight_dispatcher(port=0, rcvbuf_bytes=32 * 1024, budget_s=0.002)
    executed = []
    dispatcher._handlers[DICTIONARY.command("SET_MODE").opcode] = lambda mode: executed.append(mode)
    legit = _ground().protect(encode_command(DICTIONARY, "SET_MODE", ["POINTING"]), sn=1)
    sent = 0
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as attacker:
            for i in range(20_000):
                if i == 10_000:
                    attacker.sendto(legit, dispatcher.address)
                attacker.sendto(os.urandom(40), dispatcher.address)
                sent += 1 + (i == 10_000)
                if i % 2000 == 0:
                    dispatcher.poll()  # the GNC cycles go on meanwhile, each within its budget
        handled = dispatcher.counters["received"]
        while dispatcher.poll():
            handled = dispatcher.counters["received"]
        hk = dispatcher.hk_values()
        assert handled + hk["tc_uplink_dropped"] == sent
        assert hk["tc_uplink_dropped"] > 0  # the flood did overflow the buffer ...
        assert executed == ["POINTING"] or hk["tc_uplink_dropped"] > 0  # ... and a loss is never silent
    finally:
        dispatcher.close()


def test_a_poll_reads_until_empty_within_its_budget_and_leaves_the_rest_queued() -> None:
    ground = _ground()
    commands = [ground.protect(encode_command(DICTIONARY, "NOOP", seq_count=i), sn=i + 1) for i in range(500)]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as uplink:
        dispatcher = _flight_dispatcher(port=0, window=1000, rcvbuf_bytes=4 * 1024 * 1024, budget_s=1.0)
        try:
            for raw in commands:
                uplink.sendto(raw, dispatcher.address)
            assert len(dispatcher.poll()) == 500  # all of them in one cycle, not 64
            assert dispatcher.hk_values()["tc_uplink_deferred"] == 0
        finally:
            dispatcher.close()
        dispatcher = _flight_dispatcher(port=0, window=1000, rcvbuf_bytes=4 * 1024 * 1024, budget_s=0.0)
        try:
            for raw in commands:
                uplink.sendto(raw, dispatcher.address)
            first = dispatcher.poll()
            assert len(first) < 500 and dispatcher.hk_values()["tc_uplink_deferred"] == 1  # out of time
            rest = [r for _ in range(500) for r in dispatcher.poll()]
            assert len(first) + len(rest) == 500 and all(r.accepted for r in first + rest)  # nothing lost
            assert dispatcher.hk_values()["tc_uplink_dropped"] == 0
        finally:
            dispatcher.close()


def test_telecommand_socket_binds_loopback_unless_explicitly_allowed() -> None:
    from fsw.config import FswConfigError, parse_fsw_config

    with pytest.raises(FswConfigError, match="telecommand_bind_host '0.0.0.0' is not a loopback address"):
        parse_fsw_config({"tmtc": {"telecommand_bind_host": "0.0.0.0"}})
    cfg = parse_fsw_config({"tmtc": {"telecommand_bind_host": "0.0.0.0", "allow_non_loopback": True}})
    assert any("not loopback" in w for w in cfg.tmtc.warnings())
    assert parse_fsw_config({"tmtc": {"telecommand_bind_host": "127.0.0.2"}}).tmtc.warnings() == []


def test_mac_is_truncated_hmac_sha256() -> None:
    """Checked against an independent computation of HMAC-SHA256 with the derived key."""
    import hashlib
    import hmac

    plain = encode_command(DICTIONARY, "NOOP")
    secured = SecurityAssociation(KEY, SPI_TC).protect(plain, sn=9)
    subkey = hmac.new(KEY, b"keepout SDLS TC", hashlib.sha256).digest()
    assert secured[-2 - MAC_LEN:-2] == hmac.new(subkey, secured[:-2 - MAC_LEN], hashlib.sha256).digest()[:MAC_LEN]
    assert int.from_bytes(secured[6:8], "big") == SPI_TC and int.from_bytes(secured[8:12], "big") == 9


def test_config_validate_refuses_a_non_loopback_uplink_and_warns_when_it_is_allowed(tmp_path, capsys) -> None:
    import yaml

    from cli.main import main
    from keepout_config import config_path

    mission = yaml.safe_load(config_path("missions", "demo-pointing.yaml").read_text())
    tmtc = mission["flight_software"].setdefault("tmtc", {})
    tmtc["telecommand_bind_host"] = "0.0.0.0"
    path = tmp_path / "open.yaml"
    path.write_text(yaml.safe_dump(mission))
    assert main(["config", "validate", str(path)]) != 0
    assert "not a loopback address" in capsys.readouterr().err
    tmtc["allow_non_loopback"] = True
    path.write_text(yaml.safe_dump(mission))
    assert main(["config", "validate", str(path)]) == 0
    captured = capsys.readouterr()
    assert "warning" in captured.err and "0.0.0.0" in captured.err and "valid" in captured.out


def test_uplink_junk_is_housekeeping_not_a_flood_of_warning_events() -> None:
    """Junk on the uplink used to raise a WARNING_HI CMD_REJECTED event each (7,321 throttled in one run): an
    attacker controlled the warnings. Now junk is counted per reason in housekeeping and summarised by one
    UPLINK_JUNK event a minute at most; a command that authenticates and is refused still raises CMD_REJECTED."""
    import random

    from fsw.telemetry import TelemetrySender

    now = [0.0]
    telemetry = TelemetrySender(DICTIONARY, port=None, clock=lambda: now[0])
    dispatcher = CommandDispatcher(DICTIONARY, telemetry, port=None, security=uplink_receiver(KEY, 16))
    dispatcher.register("NOOP", lambda: None)
    dispatcher.register("SET_MODE", lambda mode: None)
    rnd = random.Random(3)
    forged = SecurityAssociation(bytes(32), SPI_TC)
    n = 0
    for step in range(3000):  # 300 s of onboard time, junk every 0.1 s: random bytes and forged MACs
        now[0] = 0.1 * step
        junk = (bytes(rnd.getrandbits(8) for _ in range(rnd.randint(1, 80))) if step % 2
                else forged.protect(encode_command(DICTIONARY, "NOOP", seq_count=step % 16000), sn=step + 1))
        dispatcher.handle_datagram(junk)
        n += 1
    hk = dispatcher.hk_values()
    assert hk["tc_uplink_junk"] == n
    assert hk["tc_sec_bad_mac"] + hk["tc_sec_unauthenticated"] + hk["tc_format_errors"] == n  # per reason
    assert hk["tc_sec_bad_mac"] == n // 2
    events = [e for e in telemetry.recent_events]
    assert not [e for e in events if e.name == "CMD_REJECTED"]
    summaries = [e for e in events if e.name == "UPLINK_JUNK"]
    assert 5 <= len(summaries) <= 6  # the first at once, then one a minute over 300 s
    assert sum(e.args["count"] for e in summaries) <= n
    # an authenticated command that is refused (an unknown mode) is the ground's business: an event each
    ground = _ground()
    bad = bytearray(encode_command(DICTIONARY, "SET_MODE", ["POINTING"], seq_count=1))
    bad[8] = 200  # mode index out of range
    from comms.telemetry import crc16_ccitt

    bad = bytes(bad[:-2]) + crc16_ccitt(bytes(bad[:-2])).to_bytes(2, "big")
    result = dispatcher.handle_datagram(ground.protect(bad, sn=10_000))
    assert not result.accepted
    assert [e.name for e in telemetry.recent_events][-1] == "CMD_REJECTED"
