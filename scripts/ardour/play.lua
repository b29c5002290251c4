-- Run by play.sh in ardour7-lua (Ardour's session interpreter, no GUI): a session on the dummy
-- backend, a MIDI track with unacorda (VST3) as its instrument and the test notes (notes.lua)
-- before it (a chord at 0.5 s under the sustain pedal, the keys let go at 1.0 s, the pedal at
-- 2.0 s); the track's meter read every 50 ms for 4 s. Prints one line per 0.5 s and the
-- summary play.sh checks.
AudioEngine:set_backend ("None (Dummy)", "", "")
-- The meter follows the signal down at once (its default falls 13 dB/s, slower than a damper).
ARDOUR.config ():set_meter_falloff (1000)
local dir = os.getenv ("UNACORDA_SESSION")
local s = create_session (dir, "unacorda", 48000)
assert (s, "no session")
local info = ARDOUR.LuaAPI.new_plugin_info ("unacorda", ARDOUR.PluginType.VST3)
assert (not info:isnil (), "Ardour does not know unacorda (VST3): is it in ~/.vst3 and scanned?")
local tracks = s:new_midi_track (ARDOUR.ChanCount (ARDOUR.DataType ("midi"), 1),
	ARDOUR.ChanCount (ARDOUR.DataType ("audio"), 2), true, info, nil, nil, 1, "piano",
	ARDOUR.PresentationInfo.max_order, ARDOUR.TrackMode.Normal, true, false)
local track = tracks:front ()
local notes = ARDOUR.LuaAPI.new_luaproc (s, "unacorda test notes")
assert (not notes:isnil (), "no test notes (notes.lua)")
assert (track:add_processor_by_index (notes, 0, nil, true) == 0, "the notes not placed before the plugin")
for i = 0, 4 do
	local p = track:nth_plugin (i)
	if p:isnil () then break end
	print ("processor " .. i .. ": " .. p:display_name ())
end
-- The meter's channel 0 is the track's MIDI; 1 and 2 the plugin's left and right.
local meter = track:peak_meter ()
local peak, first, held, late, window = { -200, -200 }, nil, -200, -200, -200
for step = 1, 80 do
	ARDOUR.LuaAPI.usleep (50000)
	for c = 1, 2 do
		local db = meter:meter_level (c, ARDOUR.MeterType.MeterPeak)
		peak[c] = math.max (peak[c], db)
		window = math.max (window, db)
		if db > -60 and not first then first = step * 0.05 end
		if step > 30 and step <= 40 then held = math.max (held, db) end
		if step > 70 then late = math.max (late, db) end
	end
	if step % 10 == 0 then
		print (string.format ("%.1f s: peak %.1f dBFS", step * 0.05, window))
		window = -200
	end
end
print (string.format ("summary: first sound by %s s, peaks %.1f / %.1f dBFS, 1.5-2 s %.1f dBFS, 3.5-4 s %.1f dBFS",
	first and string.format ("%.2f", first) or "never", peak[1], peak[2], held, late))
close_session ()
