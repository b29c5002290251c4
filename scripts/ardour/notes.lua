ardour {
	["type"]    = "dsp",
	name        = "unacorda test notes",
	category    = "Utility",
	license     = "MIT",
	author      = "unacorda",
	description = [[The test notes of unacorda's scripts/ardour/play.sh: a chord at 0.5 s under the sustain pedal (CC64), the keys let go at 1.0 s, the pedal at 2.0 s, into the instrument after it]]
}

-- Counts samples from its first block, whatever the transport: the session's processors run
-- while it is stopped.

function dsp_ioconfig () return { { midi_in = 1, midi_out = 1, audio_in = 0, audio_out = 0 }, } end

local rate = 48000
local pos = 0
local script = {
	{ 0.5, { 0xB0, 64, 127 } },
	{ 0.5, { 0x90, 60, 100 } },
	{ 0.5, { 0x90, 64, 90 } },
	{ 0.5, { 0x90, 67, 90 } },
	{ 1.0, { 0x80, 60, 64 } },
	{ 1.0, { 0x80, 64, 64 } },
	{ 1.0, { 0x80, 67, 64 } },
	{ 2.0, { 0xB0, 64, 0 } },
}

function dsp_init (r) rate = r end

function dsp_run (_, _, n_samples)
	local cnt = 1
	for _, e in ipairs (script) do
		local t = math.floor (e[1] * rate)
		if t >= pos and t < pos + n_samples then
			midiout[cnt] = { time = t - pos + 1, data = e[2] }
			cnt = cnt + 1
		end
	end
	pos = pos + n_samples
end
