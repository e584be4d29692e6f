-- navtwin's Wireshark dissectors: the SINS board frame, the nanoLOC gateway report and the
-- XBee API frames of the emulated lab (wire-formats.md sections 1-3), for the captures
-- `navtwin pcap` and `navtwin extcap` write.
--
--   tshark -X lua_script:$(navtwin pcap --dissectors) -r capture.pcapng
--   or copy this file to ~/.local/lib/wireshark/plugins/ (Wireshark's personal plugins folder)
--
-- Wireshark 4.0 has no XBee API dissector (`tshark -G protocols` lists none), so this file
-- brings one. Protocols and their filter fields (docs/testing.md, "Captures in Wireshark"):
--   navtwin.sins     seq, every register word raw (navtwin.sins.xgyro_out) and in units
--                    (navtwin.sins.xgyro_dps, _g, _c, _v), nd, ea, crc, crc_ok; a magnetometer
--                    frame (type 02): xmag, ymag, zmag raw and xmag_ut .. in uT, mag_overflow;
--                    a wide sample (type 03): x_gyro .. z_accl (32-bit words) raw, the same
--                    unit fields (navtwin.sins.xgyro_dps ..) and the housekeeping words
--   navtwin.nanoloc  seq, t_us, anchor, tag, status, rssi, tau1..tau4 (ps), distance_m, crc_ok;
--                    a wide ranging report (type 02) has the same fields, its ids 16-bit
--   navtwin.xbee     start, length, type, the frame's fields (src64, src16, options, rf_data,
--                    command, at_status, ...), checksum, checksum_ok; 0x90 RF data is
--                    dissected as the SINS stream it carries; API mode 2 (escaped) on
--                    USER2, mode 1 on USER3 (framed by navtwin.xbee_api1, shown as navtwin.xbee)
--   navtwin.garbage  bytes of a packet that are no complete frame
--   the air          ZigBee APS payloads of Digi's profile 0xC105 are dissected as SINS frames
--
-- A packet is one chunk of a port's byte stream: every complete frame in it is dissected, the
-- rest shows as garbage / partial frame. Frames split across packets are not reassembled.
-- A frame whose CRC or checksum fails is shown, flagged (crc_ok false, an expert error); the
-- search resyncs as navtwin's stream decoders do (protocols/stream.py): a candidate that
-- fails its length or integrity check is left one byte after its start (API mode 2: at the
-- next bare 7E).

-- Link types (wtap encapsulations USER0.. = LINKTYPE_USER0 147..): protocols/capture.py
-- LINKTYPES says the same, tests/protocols/test_capture.py checks that they agree.
local LINKTYPES = {
    sins = wtap.USER0,
    nanoloc = wtap.USER1,
    xbee_escaped = wtap.USER2,
    xbee = wtap.USER3,
}

-- CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF), the SINS and nanoLOC frames' check
local CRC_TABLE = {}
for i = 0, 255 do
    local c = bit32.lshift(i, 8)
    for _ = 1, 8 do
        if bit32.btest(c, 0x8000) then
            c = bit32.bxor(bit32.lshift(c, 1), 0x1021)
        else
            c = bit32.lshift(c, 1)
        end
    end
    CRC_TABLE[i] = bit32.band(c, 0xFFFF)
end

local function crc16(s, first, last) -- over bytes first..last (1-based) of string s
    local c = 0xFFFF
    for k = first, last do
        local t = bit32.bxor(bit32.rshift(c, 8), s:byte(k))
        c = bit32.band(bit32.bxor(bit32.lshift(c, 8), CRC_TABLE[t]), 0xFFFF)
    end
    return c
end

-- A protocol's fields (declared by name in a table) as the list Proto.fields takes
local function field_list(fields)
    local list = {}
    for _, f in pairs(fields) do list[#list + 1] = f end
    return list
end

-- The expert info of a failed integrity check (CRC, checksum): an error
local function checksum_expert(name, text)
    return ProtoExpert.new(name, text, expert.group.CHECKSUM, expert.severity.ERROR)
end

local function signed(v, bits)
    local half = 2 ^ (bits - 1)
    v = v % (2 * half)
    if v >= half then return v - 2 * half end
    return v
end

local function u16(s, k) return s:byte(k) * 256 + s:byte(k + 1) end

-- Garbage: what no frame of a packet claims
local garbage = Proto("navtwin.garbage", "navtwin garbage / partial frame")
local f_garbage = ProtoField.bytes("navtwin.garbage.data", "Bytes")
garbage.fields = { f_garbage }
local e_garbage = ProtoExpert.new("navtwin.garbage.expert", "Garbage / partial frame (not reassembled)",
    expert.group.UNDECODED, expert.severity.WARN)
garbage.experts = { e_garbage }

local function show_garbage(tvb, tree, from, to)
    if to > from then
        local item = tree:add(garbage, tvb(from, to - from))
        item:add(f_garbage, tvb(from, to - from))
        item:add_proto_expert_info(e_garbage)
    end
end

-- The scan every stream shares. judge(s, st, n) looks at the candidate starting at offset st
-- (0-based) of the packet's bytes s (n of them) and says
--   "frame", size          an intact frame of size bytes
--   "bad", size            a frame whose check failed: shown, flagged, then resync
--   "none", resume         no frame here (bad length, cut short, bad escape): search on from resume
-- show(tvb, st, size, ok, tree) adds a frame and returns a few words for the Info column.
-- Returns the Info words of the frames, in order.
local function scan(tvb, tree, sync, judge, show)
    local s = tvb:raw()
    local n = #s
    local covered, j, info = 0, 0, {}
    while true do
        local p = s:find(sync, j + 1, true)
        if not p then break end
        local st = p - 1
        local verdict, size = judge(s, st, n)
        if verdict == "frame" or (verdict == "bad" and st >= covered) then
            show_garbage(tvb, tree, covered, st)
            info[#info + 1] = show(tvb, st, size, verdict == "frame", tree)
            covered = math.max(covered, st + size)
        end
        if verdict == "frame" then
            j = st + size
        elseif verdict == "bad" then
            j = st + 1
        else
            j = math.max(size, st + 1)
        end
    end
    show_garbage(tvb, tree, covered, n)
    return info
end

-- The framing of the SINS frame and the nanoLOC report: sync(2) type len payload crc16.
-- fixed: type -> the only length that type may have (others are skipped by len).
local function crc_framed_judge(fixed)
    return function(s, st, n)
        if n - st < 4 then return "none", n end
        local ftype, len = s:byte(st + 3), s:byte(st + 4)
        local size = len + 6
        if fixed[ftype] and fixed[ftype] ~= len then return "none", st + 1 end
        if st + size > n then return "none", st + 1 end
        local ok = crc16(s, st + 3, st + size - 2) == u16(s, st + size - 1)
        return ok and "frame" or "bad", size
    end
end

local function info_line(name, info)
    if #info == 0 then return name .. ": garbage / partial frame" end
    if #info == 1 then return name .. " " .. info[1] end
    return name .. " " .. info[1] .. " .. " .. info[#info] .. " (" .. #info .. " frames)"
end

-- 1. SINS board frame (ADIS16350 register words; protocols/sins.py, protocols/adis16350.py)
local sins = Proto("navtwin.sins", "navtwin SINS board frame (ADIS16350)")
local GYRO_LSB_DPS = { [300] = 0.07326, [150] = 0.03663, [75] = 0.018315 }
-- name, raw field, unit field, its label, bits, signed, LSB (nil: the gyro range's), offset
local WORDS = {
    { "SUPPLY_OUT", "supply_v", "V", 12, false, 1.8315e-3, 0 },
    { "XGYRO_OUT", "xgyro_dps", "deg/s", 14, true, nil, 0 },
    { "YGYRO_OUT", "ygyro_dps", "deg/s", 14, true, nil, 0 },
    { "ZGYRO_OUT", "zgyro_dps", "deg/s", 14, true, nil, 0 },
    { "XACCL_OUT", "xaccl_g", "g", 14, true, 2.522e-3, 0 },
    { "YACCL_OUT", "yaccl_g", "g", 14, true, 2.522e-3, 0 },
    { "ZACCL_OUT", "zaccl_g", "g", 14, true, 2.522e-3, 0 },
    { "XTEMP_OUT", "xtemp_c", "degC", 12, true, 0.1453, 25.0 },
    { "YTEMP_OUT", "ytemp_c", "degC", 12, true, 0.1453, 25.0 },
    { "ZTEMP_OUT", "ztemp_c", "degC", 12, true, 0.1453, 25.0 },
    { "AUX_ADC", "aux_v", "V", 12, false, 0.6105e-3, 0 },
}
local sf = {
    sync = ProtoField.uint16("navtwin.sins.sync", "Sync", base.HEX),
    type = ProtoField.uint8("navtwin.sins.type", "Type", base.HEX,
        { [1] = "sample", [2] = "magnetometer", [3] = "wide sample" }),
    len = ProtoField.uint8("navtwin.sins.len", "Payload length", base.DEC),
    seq = ProtoField.uint16("navtwin.sins.seq", "Sample counter", base.DEC),
    nd = ProtoField.bool("navtwin.sins.nd", "New data (ND) in every word"),
    ea = ProtoField.bool("navtwin.sins.ea", "Error/alarm (EA) in some word"),
    payload = ProtoField.bytes("navtwin.sins.payload", "Payload (unknown type)"),
    crc = ProtoField.uint16("navtwin.sins.crc", "CRC-16", base.HEX),
    crc_ok = ProtoField.bool("navtwin.sins.crc_ok", "CRC OK"),
}
for _, w in ipairs(WORDS) do
    sf[w[1]] = ProtoField.uint16("navtwin.sins." .. w[1]:lower(), w[1], base.HEX)
    sf[w[2]] = ProtoField.double("navtwin.sins." .. w[2], w[1] .. " (" .. w[3] .. ")")
end
-- the magnetometer frame (type 02): HMC5883L words, 1090 LSB/gauss, -4096 = overflow
local MAG_LSB_UT, MAG_OVERFLOW = 100 / 1090, -4096
local MAG_AXES = { "x", "y", "z" }
for _, a in ipairs(MAG_AXES) do
    sf[a .. "mag"] = ProtoField.int16("navtwin.sins." .. a .. "mag", a:upper() .. "MAG", base.DEC)
    sf[a .. "mag_ut"] = ProtoField.double("navtwin.sins." .. a .. "mag_ut", a:upper() .. "MAG (uT)")
end
sf.mag_overflow = ProtoField.bool("navtwin.sins.mag_overflow", "Magnetometer overflow (an axis reads -4096)")
-- the wide sample frame (type 03): 32-bit gyro and accelerometer words, each an ADIS16488A
-- register pair X_GYRO_OUT:X_GYRO_LOW (protocols/adis16488.py), shown in the sample's unit
-- fields; the housekeeping words are type 01's (WORDS 1 and 8..11)
local WIDE = {
    { "X_GYRO", "xgyro_dps", 0.02 / 65536 }, { "Y_GYRO", "ygyro_dps", 0.02 / 65536 },
    { "Z_GYRO", "zgyro_dps", 0.02 / 65536 }, { "X_ACCL", "xaccl_g", 0.8e-3 / 65536 },
    { "Y_ACCL", "yaccl_g", 0.8e-3 / 65536 }, { "Z_ACCL", "zaccl_g", 0.8e-3 / 65536 },
}
local WIDE_HOUSEKEEPING = { { 1, 6 }, { 8, 32 }, { 9, 34 }, { 10, 36 }, { 11, 38 } } -- WORDS index, frame offset
for _, w in ipairs(WIDE) do
    sf[w[1]] = ProtoField.int32("navtwin.sins." .. w[1]:lower(), w[1] .. "_OUT:" .. w[1] .. "_LOW", base.DEC)
end
sins.fields = field_list(sf)
local e_bad_crc = checksum_expert("navtwin.sins.bad_crc", "Bad CRC-16")
sins.experts = { e_bad_crc }
sins.prefs.gyro_range = Pref.enum("Gyro range (deg/s)", 300,
    "ADIS16350 dynamic range (SENS/AVG): sets the gyro words' LSB",
    { { 1, "300", 300 }, { 2, "150", 150 }, { 3, "75", 75 } }, false)

-- One ADIS16350 register word at offset at (0-based) of the frame s: its raw and unit
-- fields; returns its ND and EA bits
local function show_word(tvb, st, s, w, at, t)
    local raw = u16(s, at + 1)
    local count = raw % 2 ^ w[4]
    if w[5] then count = signed(count, w[4]) end
    local lsb = w[6] or GYRO_LSB_DPS[sins.prefs.gyro_range]
    t:add(sf[w[1]], tvb(st + at, 2))
    t:add(sf[w[2]], tvb(st + at, 2), count * lsb + w[7])
    return raw >= 0x8000, bit32.btest(raw, 0x4000)
end

local function show_sins(tvb, st, size, ok, tree)
    local fr = tvb(st, size)
    local t = tree:add(sins, fr)
    local s = fr:raw()
    t:add(sf.sync, tvb(st, 2))
    t:add(sf.type, tvb(st + 2, 1))
    t:add(sf.len, tvb(st + 3, 1))
    local words = s:byte(3) == 1 and s:byte(4) == 24
    local seq = nil
    if words then
        seq = u16(s, 5)
        t:add(sf.seq, tvb(st + 4, 2))
        local nd, ea = true, false
        for k, w in ipairs(WORDS) do
            local n, e = show_word(tvb, st, s, w, 6 + 2 * (k - 1), t)
            nd, ea = nd and n, ea or e
        end
        t:add(sf.nd, tvb(st + 6, 22), nd)
        t:add(sf.ea, tvb(st + 6, 22), ea)
    elseif s:byte(3) == 3 and s:byte(4) == 36 then
        seq = u16(s, 5)
        t:add(sf.seq, tvb(st + 4, 2))
        local nd, ea = true, false
        for _, h in ipairs(WIDE_HOUSEKEEPING) do
            local n, e = show_word(tvb, st, s, WORDS[h[1]], h[2], t)
            nd, ea = nd and n, ea or e
        end
        for k, w in ipairs(WIDE) do
            local at = 8 + 4 * (k - 1)
            local count = signed(u16(s, at + 1) * 65536 + u16(s, at + 3), 32)
            t:add(sf[w[1]], tvb(st + at, 4))
            t:add(sf[w[2]], tvb(st + at, 4), count * w[3])
        end
        t:add(sf.nd, tvb(st + 6, 34), nd)
        t:add(sf.ea, tvb(st + 6, 34), ea)
    elseif s:byte(3) == 2 and s:byte(4) == 8 then
        seq = u16(s, 5)
        t:add(sf.seq, tvb(st + 4, 2))
        local over = false
        for k, a in ipairs(MAG_AXES) do
            local at = st + 6 + 2 * (k - 1)
            local count = signed(u16(s, 7 + 2 * (k - 1)), 16)
            t:add(sf[a .. "mag"], tvb(at, 2))
            if count == MAG_OVERFLOW then
                over = true
            else
                t:add(sf[a .. "mag_ut"], tvb(at, 2), count * MAG_LSB_UT)
            end
        end
        t:add(sf.mag_overflow, tvb(st + 6, 6), over)
    elseif size > 6 then
        t:add(sf.payload, tvb(st + 4, size - 6))
    end
    t:add(sf.crc, tvb(st + size - 2, 2))
    local item = t:add(sf.crc_ok, tvb(st + size - 2, 2), ok)
    if not ok then item:add_proto_expert_info(e_bad_crc) end
    t:append_text((seq and (", seq " .. seq) or "") .. (ok and "" or " [bad CRC]"))
    local what = seq and ((s:byte(3) == 2 and "mag seq " or "seq ") .. seq) or ("type " .. s:byte(3))
    return what .. (ok and "" or " bad CRC")
end

local judge_sins = crc_framed_judge({ [1] = 24, [2] = 8, [3] = 36 })

-- The SINS frames in tvb (a port's packet or the RF data of an XBee 0x90 frame): Info words
local function dissect_sins(tvb, tree)
    return scan(tvb, tree, "\165\090", judge_sins, show_sins)
end

function sins.dissector(tvb, pinfo, tree)
    pinfo.cols.protocol = "SINS"
    pinfo.cols.info = info_line("SINS", dissect_sins(tvb, tree))
    return tvb:len()
end

-- 2. nanoLOC gateway report (protocols/nanoloc.py)
local nanoloc = Proto("navtwin.nanoloc", "navtwin nanoLOC gateway ranging report")
local STATUS = { [0x0F] = "complete exchange", [0x40] = "timeout (no response)", [0x80] = "value error" }
local nf = {
    sync = ProtoField.uint16("navtwin.nanoloc.sync", "Sync", base.HEX),
    type = ProtoField.uint8("navtwin.nanoloc.type", "Type", base.HEX, { [1] = "ranging report",
                                                                        [2] = "wide ranging report" }),
    len = ProtoField.uint8("navtwin.nanoloc.len", "Payload length", base.DEC),
    seq = ProtoField.uint16("navtwin.nanoloc.seq", "Report counter", base.DEC),
    t_us = ProtoField.uint32("navtwin.nanoloc.t_us", "Anchor-network time (us)", base.DEC),
    anchor = ProtoField.uint16("navtwin.nanoloc.anchor", "Anchor", base.DEC),
    tag = ProtoField.uint16("navtwin.nanoloc.tag", "Tag", base.HEX),
    status = ProtoField.uint8("navtwin.nanoloc.status", "Status", base.HEX, STATUS),
    tau1_valid = ProtoField.bool("navtwin.nanoloc.status.tau1_valid", "tau1 valid", 8, nil, 0x01),
    tau2_valid = ProtoField.bool("navtwin.nanoloc.status.tau2_valid", "tau2 valid", 8, nil, 0x02),
    tau3_valid = ProtoField.bool("navtwin.nanoloc.status.tau3_valid", "tau3 valid", 8, nil, 0x04),
    tau4_valid = ProtoField.bool("navtwin.nanoloc.status.tau4_valid", "tau4 valid", 8, nil, 0x08),
    timeout = ProtoField.bool("navtwin.nanoloc.status.timeout", "Timeout", 8, nil, 0x40),
    value_error = ProtoField.bool("navtwin.nanoloc.status.value_error", "Value error", 8, nil, 0x80),
    complete = ProtoField.bool("navtwin.nanoloc.complete", "Complete exchange"),
    rssi = ProtoField.int8("navtwin.nanoloc.rssi", "RSSI (dBm)", base.DEC),
    tau1 = ProtoField.uint32("navtwin.nanoloc.tau1", "tau1, anchor: response round trip (ps)", base.DEC),
    tau2 = ProtoField.uint32("navtwin.nanoloc.tau2", "tau2, tag: its processing (ps)", base.DEC),
    tau3 = ProtoField.uint32("navtwin.nanoloc.tau3", "tau3, tag: response round trip (ps)", base.DEC),
    tau4 = ProtoField.uint32("navtwin.nanoloc.tau4", "tau4, anchor: its processing (ps)", base.DEC),
    distance_m = ProtoField.double("navtwin.nanoloc.distance_m", "Distance c(tau1-tau2+tau3-tau4)/4 (m)"),
    payload = ProtoField.bytes("navtwin.nanoloc.payload", "Payload (unknown type)"),
    crc = ProtoField.uint16("navtwin.nanoloc.crc", "CRC-16", base.HEX),
    crc_ok = ProtoField.bool("navtwin.nanoloc.crc_ok", "CRC OK"),
}
nanoloc.fields = field_list(nf)
local e_nl_bad_crc = checksum_expert("navtwin.nanoloc.bad_crc", "Bad CRC-16")
nanoloc.experts = { e_nl_bad_crc }
local SPEED_OF_LIGHT = 299792458.0 -- m/s

local function show_nanoloc(tvb, st, size, ok, tree)
    local t = tree:add(nanoloc, tvb(st, size))
    local s = tvb(st, size):raw()
    t:add(nf.sync, tvb(st, 2))
    t:add(nf.type, tvb(st + 2, 1))
    t:add(nf.len, tvb(st + 3, 1))
    local words = ""
    -- the id width: 1 byte in a ranging report (type 01), 2 in a wide one (type 02)
    local w = (s:byte(3) == 1 and s:byte(4) == 26 and 1) or (s:byte(3) == 2 and s:byte(4) == 28 and 2)
    if w then
        t:add(nf.seq, tvb(st + 4, 2))
        t:add(nf.t_us, tvb(st + 6, 4))
        t:add(nf.anchor, tvb(st + 10, w))
        t:add(nf.tag, tvb(st + 10 + w, w))
        local at = st + 10 + 2 * w  -- status
        local status = t:add(nf.status, tvb(at, 1))
        for _, bit in ipairs({ "tau1_valid", "tau2_valid", "tau3_valid", "tau4_valid", "timeout", "value_error" }) do
            status:add(nf[bit], tvb(at, 1))
        end
        local code = tvb(at, 1):uint()
        local complete = bit32.band(code, 0xCF) == 0x0F
        t:add(nf.complete, tvb(at, 1), complete)
        t:add(nf.rssi, tvb(at + 1, 1))
        local tau = {}
        for k = 1, 4 do
            t:add(nf["tau" .. k], tvb(at + 4 * k - 2, 4))
            tau[k] = tvb(at + 4 * k - 2, 4):uint()
        end
        words = "anchor " .. tvb(st + 10, w):uint()
        if complete then
            -- as protocols/nanoloc.distance computes it, operation for operation
            local d = SPEED_OF_LIGHT * (tau[1] - tau[2] + tau[3] - tau[4]) * 1e-12 / 4.0
            t:add(nf.distance_m, tvb(at + 2, 16), d)
            words = words .. string.format(" %.3f m", d)
        else
            words = words .. string.format(" status 0x%02X", code)
        end
    else
        if size > 6 then t:add(nf.payload, tvb(st + 4, size - 6)) end
        words = "type " .. s:byte(3)
    end
    t:add(nf.crc, tvb(st + size - 2, 2))
    local item = t:add(nf.crc_ok, tvb(st + size - 2, 2), ok)
    if not ok then item:add_proto_expert_info(e_nl_bad_crc) end
    t:append_text(", " .. words .. (ok and "" or " [bad CRC]"))
    return words .. (ok and "" or " bad CRC")
end

local judge_nanoloc = crc_framed_judge({ [1] = 26, [2] = 28 })

function nanoloc.dissector(tvb, pinfo, tree)
    pinfo.cols.protocol = "nanoLOC"
    pinfo.cols.info = info_line("nanoLOC", scan(tvb, tree, "NL", judge_nanoloc, show_nanoloc))
    return tvb:len()
end

-- 3. XBee API frames (protocols/xbee.py): 7E | length (2) | frame data | checksum
local xbee = Proto("navtwin.xbee", "navtwin XBee API frame (Digi ZigBee API)")
local MAX_FRAME_DATA = 1024 -- the bound navtwin's decoders put on the length field
local FRAME_TYPES = {
    [0x08] = "at_command", [0x09] = "at_command_queue", [0x10] = "transmit_request",
    [0x11] = "explicit_addressing", [0x17] = "remote_at_request", [0x88] = "at_response",
    [0x8A] = "modem_status", [0x8B] = "transmit_status", [0x90] = "receive_packet",
    [0x91] = "explicit_rx", [0x95] = "node_identification", [0x97] = "remote_at_response",
}
local AT_STATUS = { [0] = "OK", [1] = "error", [2] = "invalid command", [3] = "invalid parameter",
    [4] = "TX failure" }
local MODEM_STATUS = { [0x00] = "hardware reset", [0x01] = "watchdog timer reset",
    [0x02] = "joined network", [0x03] = "disassociated", [0x06] = "coordinator started",
    [0x07] = "network security key updated", [0x0D] = "voltage supply limit exceeded",
    [0x11] = "modem configuration changed while join in progress" }
local DELIVERY = { [0x00] = "success", [0x01] = "MAC ACK failure", [0x02] = "CCA failure",
    [0x21] = "network ACK failure", [0x22] = "not joined", [0x23] = "self-addressed",
    [0x24] = "address not found", [0x25] = "route not found", [0x74] = "payload too large" }
local DEVICE_TYPE = { [0] = "coordinator", [1] = "router", [2] = "end device" }
local xf = {
    start = ProtoField.uint8("navtwin.xbee.start", "Start delimiter", base.HEX),
    length = ProtoField.uint16("navtwin.xbee.length", "Length", base.DEC),
    type = ProtoField.uint8("navtwin.xbee.type", "Frame type", base.HEX, FRAME_TYPES),
    frame_id = ProtoField.uint8("navtwin.xbee.frame_id", "Frame ID", base.DEC),
    dest64 = ProtoField.uint64("navtwin.xbee.dest64", "64-bit destination", base.HEX),
    dest16 = ProtoField.uint16("navtwin.xbee.dest16", "16-bit destination", base.HEX),
    src64 = ProtoField.uint64("navtwin.xbee.src64", "64-bit source", base.HEX),
    src16 = ProtoField.uint16("navtwin.xbee.src16", "16-bit source", base.HEX),
    remote64 = ProtoField.uint64("navtwin.xbee.remote64", "64-bit remote", base.HEX),
    remote16 = ProtoField.uint16("navtwin.xbee.remote16", "16-bit remote", base.HEX),
    parent16 = ProtoField.uint16("navtwin.xbee.parent16", "16-bit parent", base.HEX),
    radius = ProtoField.uint8("navtwin.xbee.radius", "Broadcast radius", base.DEC),
    options = ProtoField.uint8("navtwin.xbee.options", "Options", base.HEX),
    src_endpoint = ProtoField.uint8("navtwin.xbee.src_endpoint", "Source endpoint", base.HEX),
    dest_endpoint = ProtoField.uint8("navtwin.xbee.dest_endpoint", "Destination endpoint", base.HEX),
    cluster = ProtoField.uint16("navtwin.xbee.cluster", "Cluster ID", base.HEX),
    profile = ProtoField.uint16("navtwin.xbee.profile", "Profile ID", base.HEX),
    command = ProtoField.string("navtwin.xbee.command", "AT command"),
    parameter = ProtoField.bytes("navtwin.xbee.parameter", "Parameter"),
    at_status = ProtoField.uint8("navtwin.xbee.at_status", "Command status", base.DEC, AT_STATUS),
    value = ProtoField.bytes("navtwin.xbee.value", "Register value"),
    modem_status = ProtoField.uint8("navtwin.xbee.modem_status", "Modem status", base.HEX, MODEM_STATUS),
    retries = ProtoField.uint8("navtwin.xbee.retries", "Transmit retries", base.DEC),
    delivery = ProtoField.uint8("navtwin.xbee.delivery", "Delivery status", base.HEX, DELIVERY),
    discovery = ProtoField.uint8("navtwin.xbee.discovery", "Discovery status", base.HEX),
    ni = ProtoField.stringz("navtwin.xbee.ni", "Node identifier"),
    device_type = ProtoField.uint8("navtwin.xbee.device_type", "Device type", base.DEC, DEVICE_TYPE),
    source_event = ProtoField.uint8("navtwin.xbee.source_event", "Source event", base.DEC),
    manufacturer = ProtoField.uint16("navtwin.xbee.manufacturer", "Manufacturer ID", base.HEX),
    device_type_id = ProtoField.uint32("navtwin.xbee.device_type_id", "Device type identifier", base.HEX),
    rf_data = ProtoField.bytes("navtwin.xbee.rf_data", "RF data"),
    data = ProtoField.bytes("navtwin.xbee.data", "Frame data (type not dissected)"),
    checksum = ProtoField.uint8("navtwin.xbee.checksum", "Checksum", base.HEX),
    checksum_ok = ProtoField.bool("navtwin.xbee.checksum_ok", "Checksum OK"),
}
xbee.fields = field_list(xf)
local e_bad_checksum = checksum_expert("navtwin.xbee.bad_checksum", "Bad checksum")
local e_malformed = ProtoExpert.new("navtwin.xbee.malformed", "Frame data do not fit the type's layout",
    expert.group.MALFORMED, expert.severity.ERROR)
xbee.experts = { e_bad_checksum, e_malformed }

-- each type's fields after the type byte, as protocols/xbee.py declares them: name and size
-- ("rest": the remaining bytes; "cstring": up to and including a 0 byte; "optional": if present)
local AT_COMMAND = { { "frame_id", 1 }, { "command", 2 }, { "parameter", "rest" } }
local LAYOUTS = {
    [0x08] = AT_COMMAND,
    [0x09] = AT_COMMAND,
    [0x10] = { { "frame_id", 1 }, { "dest64", 8 }, { "dest16", 2 }, { "radius", 1 }, { "options", 1 },
        { "rf_data", "rest" } },
    [0x11] = { { "frame_id", 1 }, { "dest64", 8 }, { "dest16", 2 }, { "src_endpoint", 1 },
        { "dest_endpoint", 1 }, { "cluster", 2 }, { "profile", 2 }, { "radius", 1 }, { "options", 1 },
        { "rf_data", "rest" } },
    [0x17] = { { "frame_id", 1 }, { "dest64", 8 }, { "dest16", 2 }, { "options", 1 }, { "command", 2 },
        { "parameter", "rest" } },
    [0x88] = { { "frame_id", 1 }, { "command", 2 }, { "at_status", 1 }, { "value", "rest" } },
    [0x8A] = { { "modem_status", 1 } },
    [0x8B] = { { "frame_id", 1 }, { "dest16", 2 }, { "retries", 1 }, { "delivery", 1 }, { "discovery", 1 } },
    [0x90] = { { "src64", 8 }, { "src16", 2 }, { "options", 1 }, { "rf_data", "rest" } },
    [0x91] = { { "src64", 8 }, { "src16", 2 }, { "src_endpoint", 1 }, { "dest_endpoint", 1 },
        { "cluster", 2 }, { "profile", 2 }, { "options", 1 }, { "rf_data", "rest" } },
    [0x95] = { { "src64", 8 }, { "src16", 2 }, { "options", 1 }, { "remote16", 2 }, { "remote64", 8 },
        { "ni", "cstring" }, { "parent16", 2 }, { "device_type", 1 }, { "source_event", 1 },
        { "profile", 2 }, { "manufacturer", 2 }, { "device_type_id", "optional" } },
    [0x97] = { { "frame_id", 1 }, { "src64", 8 }, { "src16", 2 }, { "command", 2 }, { "at_status", 1 },
        { "value", "rest" } },
}

-- The fields of frame data at [from, to) of u (the unescaped frame: 7E, length, data, checksum):
-- whether they fit the layout, and the Info words of the SINS frames in a 0x90's RF data
local function show_fields(u, from, to, layout, t)
    local at, inner = from, nil
    for _, field in ipairs(layout) do
        local name, size = field[1], field[2]
        if size == "rest" then
            size = to - at
        elseif size == "cstring" then
            local nul = u:raw(at, to - at):find("\0", 1, true)
            if not nul then return false end
            size = nul
        elseif size == "optional" then
            size = (to - at == 4) and 4 or 0
        end
        if at + size > to then return false end
        if size > 0 then
            local item = t:add(xf[name], u(at, size))
            if name == "rf_data" and layout == LAYOUTS[0x90] then
                -- the SINS byte stream the router sends
                inner = info_line("SINS", dissect_sins(u(at, size):tvb(), item))
            end
        end
        at = at + size
    end
    return at == to, inner
end

-- Show one frame of raw bytes [st, st + size) of tvb; u: its unescaped bytes as a Tvb (tvb's
-- own range when nothing was escaped). Info words.
local function show_xbee(tvb, st, size, ok, tree, u)
    local t = tree:add(xbee, tvb(st, size))
    local len = u(1, 2):uint()
    local ftype = u(3, 1):uint()
    t:add(xf.start, u(0, 1))
    t:add(xf.length, u(1, 2))
    t:add(xf.type, u(3, 1))
    local layout, inner = LAYOUTS[ftype], nil
    if layout then
        local fits
        fits, inner = show_fields(u, 4, 3 + len, layout, t)
        if not fits then t:add_proto_expert_info(e_malformed) end
    elseif len > 1 then
        t:add(xf.data, u(4, len - 1))
    end
    t:add(xf.checksum, u(3 + len, 1))
    local item = t:add(xf.checksum_ok, u(3 + len, 1), ok)
    if not ok then item:add_proto_expert_info(e_bad_checksum) end
    local name = FRAME_TYPES[ftype] or string.format("type 0x%02X", ftype)
    t:append_text(", " .. name .. (ok and "" or " [bad checksum]"))
    return name .. (inner and (" (" .. inner .. ")") or "") .. (ok and "" or " bad checksum")
end

local function checksum_ok(s, first, last) -- frame data and checksum, 1-based inclusive
    local sum = 0
    for k = first, last do sum = sum + s:byte(k) end
    return sum % 256 == 0xFF
end

-- API mode 1: length-framed, the SINS framing's resync rule
local function judge_api1(s, st, n)
    if n - st < 3 then return "none", n end
    local len = u16(s, st + 2)
    if len == 0 or len > MAX_FRAME_DATA then return "none", st + 1 end
    if st + len + 4 > n then return "none", st + 1 end
    return checksum_ok(s, st + 4, st + len + 4) and "frame" or "bad", len + 4
end

-- API mode 2: a candidate runs to the next bare 7E (which only ever starts a frame); its bytes
-- after the 7E are unescaped (7D x -> x ^ 0x20). The unescaped frame of the last judged
-- candidate, for show: (its start, its bytes).
local unescaped = { st = -1, bytes = nil }
local ESCAPED = { [0x7E] = true, [0x7D] = true, [0x11] = true, [0x13] = true }

local function judge_api2(s, st, n)
    local stop = (s:find("\126", st + 2, true) or n + 1) - 1
    local u, k = { 0x7E }, st + 2
    local need = nil -- unescaped bytes of the whole frame, once the length is known
    while k <= stop and not (need and #u >= need) do
        local b = s:byte(k)
        if b == 0x7D then
            local x = k < stop and bit32.bxor(s:byte(k + 1), 0x20)
            if not x or not ESCAPED[x] then return "none", stop end -- bad or cut escape
            u[#u + 1], k = x, k + 2
        else
            u[#u + 1], k = b, k + 1
        end
        if #u == 3 and not need then
            local len = u[2] * 256 + u[3]
            if len == 0 or len > MAX_FRAME_DATA then return "none", stop end
            need = len + 4
        end
    end
    if not need or #u < need then return "none", stop end -- cut short by the next 7E or the packet's end
    unescaped.st, unescaped.bytes = st, u
    local sum = 0
    for i = 4, need do sum = sum + u[i] end
    return sum % 256 == 0xFF and "frame" or "bad", k - 1 - st
end

local function show_api2(tvb, st, size, ok, tree)
    local u = unescaped.bytes
    if #u == size then -- nothing was escaped: the packet's own bytes
        return show_xbee(tvb, st, size, ok, tree, tvb(st, size):tvb())
    end
    local ba = ByteArray.new()
    ba:set_size(#u)
    for i = 1, #u do ba:set_index(i - 1, u[i]) end
    return show_xbee(tvb, st, size, ok, tree, ba:tvb("XBee unescaped"))
end

local function show_api1(tvb, st, size, ok, tree)
    return show_xbee(tvb, st, size, ok, tree, tvb(st, size):tvb())
end

local function xbee_dissector(judge, show, mode)
    return function(tvb, pinfo, tree)
        pinfo.cols.protocol = "XBee API" .. mode
        local info = scan(tvb, tree, "\126", judge, show)
        pinfo.cols.info = info_line("XBee", info)
        return tvb:len()
    end
end

xbee.dissector = xbee_dissector(judge_api2, show_api2, "2")
-- API mode 1 frames: the same protocol (and fields), another framing
local xbee_api1 = Proto("navtwin.xbee_api1", "navtwin XBee API mode 1 (unescaped) framing")
xbee_api1.dissector = xbee_dissector(judge_api1, show_api1, "1")

local encap = DissectorTable.get("wtap_encap")
encap:add(LINKTYPES.sins, sins)
encap:add(LINKTYPES.nanoloc, nanoloc)
encap:add(LINKTYPES.xbee_escaped, xbee)
encap:add(LINKTYPES.xbee, xbee_api1)

-- The air (an emulator recording's air stream, IEEE 802.15.4 frames that Wireshark's own
-- wpan, ZigBee NWK and APS dissectors read): the APS payload of Digi's profile 0xC105 is the
-- router's transparent data, the board's serial stream, so it is dissected as SINS frames
-- (without this Wireshark reads it as a ZCL frame). pcall: a Wireshark without the ZigBee
-- dissectors has no such table.
pcall(function() DissectorTable.get("zbee.profile"):add(0xC105, sins) end)
